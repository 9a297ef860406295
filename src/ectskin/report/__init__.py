"""The end of the pipeline: the reproduction report (``report.md`` / ``report.html``)."""

from ectskin.report.report import PAPER, machine_info, results_table, write_report

__all__ = ["PAPER", "machine_info", "results_table", "write_report"]
