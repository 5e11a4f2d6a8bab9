"""Identification: data extraction from bench logs, least squares, posterior sampling."""
