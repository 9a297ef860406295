"""The reproduction report: ``report.md`` and ``report.html`` rendered from a metrics dict.

The heart of the report is one table, "metric · paper · this run · baselines", that sets each
number of this run beside the paper's (§4) and beside the baselines scored on the same test split,
followed by each model's margin over the *strongest* of those baselines (a model that loses to one
says so, and by how much), the ablations, the timings, the machine and the figures, after a table
of contents.

wording (how values are written) ─► tables (rows and sentences) ─► render (Markdown, HTML);
machine (what a run ran on). The package renders only: it reads no data and runs nothing.

The metrics dict is the one ``ectskin reproduce`` writes to ``metrics.json``
(:mod:`ectskin.pipeline.metrics`); every key is optional and a missing number shows as "—"::

    {"touch": {"accuracy", "n_test_frames", "n_misclassified", "misclassified",
               "n_misclassified_adjacent", "all_adjacent", "confusions",
               "baselines": {name: {"accuracy", "n_misclassified", ...}},
               "training": {"seconds", "epochs", "best_epoch", "device"},
               "robust": {"accuracy", "n_test_frames", "n_misclassified",
                          "n_misclassified_adjacent", "per_trial", "worst_trial",
                          "training": {..., "recipe"}, "recipe_description"}},
     "track": {"ad_mm_mean", "ad_mm_std", "n_test_samples", "n_test_trajectories",
               "examples": {"ad_mm": [...], "worst_ad_mm"}, "worst_trajectory",
               "baselines": {"no_motion": {"ad_mm_mean", "ad_mm_std"}, ...},
               "ablations": {"no_prior": {...}, "window_1": {...}},
               "training": {...}},
     "contact": {...}, "multi": {...}, "bound": {...}, "ect_image": {...}  (report.contact),
     "inversion": {"loc_mm_mean", "force_mae_n", "count_accuracy", "per_state", ...}
                                                                   (report.inversion),
     "timings_s": {step: seconds}, "reused": [step, ...], "machine": {...},
     "profile": "quick" | "paper", "protocol": {...}, "created_utc": "..."}
"""

from ectskin.report.machine import machine_info
from ectskin.report.render import render_html, render_markdown, write_report
from ectskin.report.tables import (
    PAPER,
    ablation_rows,
    margin_text,
    results_table,
    strongest_baseline,
)

__all__ = [
    "PAPER",
    "ablation_rows",
    "machine_info",
    "margin_text",
    "render_html",
    "render_markdown",
    "results_table",
    "strongest_baseline",
    "write_report",
]
