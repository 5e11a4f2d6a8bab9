"""Everything at the edge: files in, SI arrays out."""
