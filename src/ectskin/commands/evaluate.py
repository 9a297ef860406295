"""``ectskin evaluate RUN_DIR [--data DATA.h5] [-o DIR]``: test-set metrics, baselines and
figures of a run.

Thin wrapper over :func:`ectskin.learn.evaluate.evaluate_run`; writes ``RUN_DIR/metrics.json``
and the figures (Fig. 7 for touch, Fig. 9 / Fig. 10 for tracking) and prints a summary. On
another recording (``--data``) it writes ``RUN_DIR/metrics_<data stem>.json`` and suffixed
figures, so the run's own evaluation is never replaced; ``-o/--out DIR`` writes into DIR.
Results of an earlier evaluation are replaced only with ``--overwrite``.

Test data: the trials the run was not trained or validated on (recognised by their readouts):
the run's test split on its own recording, all of another day's recording (``--test-trials``
chooses otherwise). Calibration: ``--reference REC.h5``, else the recording's own rest state,
else the training recording's rest state stored in the run. The summary says which were taken.
"""

from __future__ import annotations

import argparse
import logging

from ectskin.commands._options import add_figure_options, add_overwrite, add_seed
from ectskin.learn.profiles import describe_recipe

#: ``--test-trials`` values: ectskin.learn.evaluate.TEST_TRIALS, listed here because importing that
#: module loads torch, which every ``ectskin`` call would pay for (a test keeps the two equal)
TEST_TRIALS = ("auto", "split", "all")

HELP = (
    "evaluate a trained run on its test split or another recording (metrics.json, baselines, "
    "figures)"
)
EXAMPLES = """\
  ectskin evaluate runs/touch                          # metrics.json + Fig. 7 in runs/touch
  ectskin evaluate runs/track --format pdf --overwrite # again, with vector figures
  ectskin evaluate runs/touch --data day2.h5           # -> runs/touch/metrics_day2.json
  ectskin evaluate runs/touch --data day2.h5 -o eval/day2 --no-baselines
  ectskin evaluate runs/touch --data unseen.h5 --reference data.h5  # calibrated on data.h5's rest
  ectskin evaluate runs/contact --data hand_off.h5 --test-trials split  # same trials, hand off
"""
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", help="run directory written by 'ectskin train'")
    p.add_argument(
        "--data",
        default=None,
        help="recording to evaluate on (default: the file named in RUN_DIR/split.json); "
        "results on another recording go to RUN_DIR/metrics_<its stem>.json",
    )
    p.add_argument(
        "--test-trials",
        choices=TEST_TRIALS,
        default="auto",
        help="which trials are test data: auto (default) every trial the run was not trained "
        "or validated on, recognised by its readouts: the run's test split on its own "
        "recording, all of another recording; split: the run's test split by trial name (the "
        "same trials simulated again, e.g. with --push-max 0); all: every trial",
    )
    p.add_argument(
        "--reference",
        metavar="REC.h5",
        default=None,
        help="a recording of the same skin whose rest state (0 ml, untouched) calibrates the "
        "data (default: the data's own rest state, else the training recording's, stored in "
        "the run). A touch run trained with 'train --reference state' or 'inflation' is "
        "always calibrated as it was trained (each state's no-contact trials of the data, or "
        "the run's inflation model), and refuses this option",
    )
    p.add_argument(
        "-o",
        "--out",
        default=None,
        help="folder for the metrics JSON and the figures (default: RUN_DIR)",
    )
    add_overwrite(p, help="replace the results of an earlier evaluation (default: refuse)")
    p.add_argument("--no-baselines", action="store_true", help="skip the baselines")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    add_figure_options(p)
    add_seed(p, help="seed of the baselines' subsampling (default 0)")


def summary_lines(metrics: dict) -> list[str]:
    """Human-readable lines of an ``evaluate_run`` result."""
    lines = []
    for block in metrics.values():
        if isinstance(block, dict) and "test_data" in block:
            lines.append(f"test data: {block['test_data']['text']}")
        if isinstance(block, dict) and "reference" in block:
            lines.append(f"calibration: {block['reference']['text']}")
    t = metrics.get("touch")
    if t:
        lines.append(
            f"touch: accuracy {100 * t['accuracy']:.2f} % ({t['misclassified']} test frames "
            f"misclassified"
            + (
                f", {t['n_misclassified_adjacent']} between adjacent regions"
                if "n_misclassified_adjacent" in t
                else ""
            )
            + ")"
            + (f" with {t['selected_model']}" if t.get("selected_model", "mlp") != "mlp" else "")
        )
        for name, c in (t.get("candidates") or {}).items():
            val = c.get("val_accuracy")
            test = c.get("test_accuracy")
            lines.append(
                f"  candidate {name}: "
                + (f"test accuracy {100 * test:.2f} %" if test is not None else c["model"])
                + (f", validation {100 * val:.2f} %" if val is not None else "")
                + (" (selected)" if c.get("selected") else "")
            )
        tr = t.get("training") or {}
        if tr.get("recipe") is not None:
            lines.append(
                f"  trained with profile {tr.get('profile', '?')!r}: "
                f"{describe_recipe(tr['recipe'])}"
            )
        for name, b in (t.get("baselines") or {}).items():
            lines.append(f"  baseline {name}: accuracy {100 * b['accuracy']:.2f} %")
        if t.get("baselines_skipped"):
            lines.append(f"  baselines skipped: {t['baselines_skipped']}")
    k = metrics.get("track")
    if k:
        lines.append(
            f"track: AD {k['ad_mm_mean']:.3f} ± {k['ad_mm_std']:.3f} mm over "
            f"{k['n_test_samples']} test samples (window {k.get('window')}, prior {k.get('prior')})"
        )
        if "worst_trajectory" in k:
            w = k["worst_trajectory"]
            lines.append(f"  worst trajectory {w['name']}: {w['ad_mm_mean']:.3f} mm")
        for name, b in (k.get("baselines") or {}).items():
            lines.append(f"  baseline {name}: AD {b['ad_mm_mean']:.3f} ± {b['ad_mm_std']:.3f} mm")
        if k.get("baselines_skipped"):
            lines.append(f"  baselines skipped: {k['baselines_skipped']}")
    c = metrics.get("contact")
    if c:
        model = c.get("selected_model", "contactnet")
        lines.append(
            "contact: " + _contact_line(c) + (f" with {model}" if model != "contactnet" else "")
        )
        for name, cand in (c.get("candidates") or {}).items():
            test = cand.get("test_loc_mm")
            val = cand.get("val_loc_mm")
            lines.append(
                f"  candidate {name}: "
                + (f"test point error {test:.2f} mm" if test is not None else cand["model"])
                + (f", validation {val:.2f} mm" if val is not None else "")
                + (" (selected)" if cand.get("selected") else "")
            )
        for name, b in (c.get("baselines") or {}).items():
            lines.append(f"  baseline {name}: " + _contact_line(b))
        for name, why in (c.get("baselines_left_out") or {}).items():
            lines.append(f"  baseline {name}: {why}")
        if c.get("baselines_skipped"):
            lines.append(f"  baselines skipped: {c['baselines_skipped']}")
    return lines


def _contact_line(c: dict) -> str:
    """One line of a contact metrics block: point error, face, force, hover, count."""

    def num(key: str, fmt: str) -> str:
        v = c.get(key)
        return format(v, fmt) if isinstance(v, int | float) else "-"

    return (
        f"point {num('loc_mm_mean', '.2f')} mm mean, {num('loc_mm_median', '.2f')} median, "
        f"{num('loc_mm_p90', '.2f')} p90; face right {num('face_accuracy', '.1%')}; force MAE "
        f"{num('force_mae_n', '.3f')} N; hover detected to {num('hover_detect_mm', 'g')} mm; "
        f"count right {num('count_accuracy', '.1%')}"
    )


def run(args: argparse.Namespace) -> int:
    # imported on use, for start-up speed: it loads torch and matplotlib, and every ``ectskin``
    # call imports all subcommand modules to build its parser
    from ectskin.learn.evaluate import evaluate_run

    metrics = evaluate_run(
        args.run_dir,
        args.data,
        baselines=not args.no_baselines,
        figures=not args.no_figures,
        seed=args.seed,
        out=args.out,
        overwrite=args.overwrite,
        figure_format=args.figure_format,
        dpi=args.dpi,
        test_trials=args.test_trials,
        reference=args.reference,
    )
    for line in summary_lines(metrics):
        print(line)  # the files written are logged by evaluate_run
    return 0
