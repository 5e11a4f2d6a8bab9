"""The uncertainty report: one self-contained ``report.html`` beside ``result.json``.

:func:`motorid.report.html.write_report` writes it; ``motorid report DIR`` and
``motorid fit … --report`` call it.  Figures come from :mod:`motorid.report.plots`,
the numbers behind them from :mod:`motorid.report.evaluate`.
"""

__all__ = ["REPORT_FILE", "write_report"]


def __getattr__(name):  # lazy: matplotlib is imported only when a report is written
    if name in __all__:
        from motorid.report import html

        return getattr(html, name)
    raise AttributeError(name)
