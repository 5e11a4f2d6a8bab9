"""The uncertainty report: one self-contained ``report.html`` beside ``result.json``.

:func:`motorid.report.html.write_report` writes it; ``motorid report DIR`` and
``motorid fit … --report`` call it.  Figures come from :mod:`motorid.report.plots`,
the numbers behind them from :mod:`motorid.report.evaluate`.
"""

from motorid.report.html import REPORT_FILE, write_report

__all__ = ["REPORT_FILE", "write_report"]
