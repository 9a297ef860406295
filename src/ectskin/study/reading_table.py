"""The reading ablation's table and figure, from the result files there are
(:mod:`ectskin.study.reading`).

:func:`summarise` reads ``OUT/results/<row>_s<seed>.json`` into one entry per (row, seed);
:func:`table_markdown` writes the rows × seeds table: per cell the paper recipe's test accuracy
(%), the epoch it kept of how many, the robust recipe's accuracy and the strongest baseline's
name and accuracy; per row the mean of the three accuracies over the seeds it has.
:func:`plot_reading` draws the same numbers (per seed small, the mean large) beside the paper's
99.88 %. :func:`write_table` writes ``OUT/reading_ablation.md``, ``OUT/reading_ablation.png`` and
``OUT/reading_ablation.json`` (:func:`summary_document`: the cells' accuracies per row and seed, the
form the report reads: ``ectskin.report.reading``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._files import save_figure_atomic, write_json_atomic, write_text_atomic
from ectskin.study.reading_rows import RESULTS, ROW_NAMES, ROWS, read_result

#: the paper's TouchMLP test accuracy (paper §4.1.3: 34 of 28 800 frames wrong)
PAPER_ACCURACY = 1.0 - 34 / 28800
TABLE_FILE = "reading_ablation.md"
FIGURE_FILE = "reading_ablation.png"
SUMMARY_FILE = "reading_ablation.json"
SUMMARY_FORMAT = "ectskin.study.reading.summary"
_NAME = re.compile(r"^(?P<row>[a-z0-9_]+)_s(?P<seed>\d+)\.json$")


def summarise(out: str | Path) -> dict[str, dict[int, dict[str, Any]]]:
    """{row: {seed: cell}} of the result files in ``out/results`` (rows in :data:`ROWS` order,
    then any others alphabetically; seeds ascending). A cell: ``paper``, ``epoch``, ``epochs``,
    ``robust``, ``baseline`` (name), ``baseline_accuracy``, ``seconds`` (dict),
    ``robust_reference`` (the robust recipe's calibration reference)."""
    folder = Path(out) / RESULTS
    found: dict[str, dict[int, dict[str, Any]]] = {}
    for path in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        m = _NAME.match(path.name)
        doc = read_result(path) if m else None
        if doc is None or m is None:
            continue
        found.setdefault(m["row"], {})[int(m["seed"])] = {
            "paper": float(doc["paper"]["accuracy"]),
            "epoch": int(doc["paper"]["best_epoch"]),
            "epochs": int(doc["paper"]["epochs"]),
            "robust": float(doc["robust"]["accuracy"]),
            "baseline": str(doc["best_baseline"]["name"]),
            "baseline_accuracy": float(doc["best_baseline"]["accuracy"]),
            "seconds": dict(doc.get("seconds", {})),
            "robust_reference": str(
                doc["settings"].get("recipes", {}).get("robust", {}).get("reference", "auto")
            ),
        }
    order = [r for r in ROW_NAMES if r in found] + sorted(set(found) - set(ROW_NAMES))
    return {r: dict(sorted(found[r].items())) for r in order}


def row_means(cells: dict[int, dict[str, Any]]) -> dict[str, float]:
    """Mean over the seeds of the paper recipe's, the robust recipe's and the strongest
    baseline's accuracy (each seed's strongest, whichever it is)."""
    keys = ("paper", "robust", "baseline_accuracy")
    return {k: float(np.mean([c[k] for c in cells.values()])) for k in keys}


def _pct(x: float) -> str:
    return f"{100 * x:.2f}"


def table_markdown(summary: dict[str, dict[int, dict[str, Any]]]) -> str:
    """The Markdown table of ``summary`` (module docstring), with a legend line."""
    seeds = sorted({s for cells in summary.values() for s in cells})
    what = {r.name: r.what for r in ROWS}
    head = ["row", *[f"seed {s}" for s in seeds], "mean: paper · robust · baseline"]
    refs = sorted({c.get("robust_reference", "auto") for cells in summary.values()
                   for c in cells.values()})
    lines = [
        "Cells: paper recipe % (epoch kept / epochs) · robust recipe % · strongest baseline %. "
        f"Paper: {_pct(PAPER_ACCURACY)} %. The paper recipe: the `quick` profile, frames "
        "calibrated against the rest state; the robust recipe: the `robust` profile, frames "
        f"calibrated against: {', '.join(f'`{r}`' for r in refs)} (\"auto\": the rest state).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "|".join(["---"] * len(head)) + "|",
    ]
    for row, cells in summary.items():
        parts = [f"`{row}`"]
        for s in seeds:
            c = cells.get(s)
            parts.append(
                "–"
                if c is None
                else f"{_pct(c['paper'])} ({c['epoch']}/{c['epochs']}) · {_pct(c['robust'])} · "
                f"{c['baseline']} {_pct(c['baseline_accuracy'])}"
            )
        m = row_means(cells)
        n = "" if len(cells) == len(seeds) else f" ({len(cells)} seed{'s' * (len(cells) > 1)})"
        parts.append(
            f"{_pct(m['paper'])} · {_pct(m['robust'])} · {_pct(m['baseline_accuracy'])}{n}"
        )
        lines.append("| " + " | ".join(parts) + " |")
    lines += ["", "Rows:", ""]
    lines += [f"- `{r}`: {what.get(r, '(not a row of this version)')}" for r in summary]
    return "\n".join(lines) + "\n"


def plot_reading(summary: dict[str, dict[int, dict[str, Any]]], axes: Any = None) -> Any:
    """Accuracy per row: the paper recipe, the robust recipe and the strongest baseline, each
    seed a small marker and the mean a large one, with the paper's 99.88 %. Returns the figure."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = list(summary)
    if axes is None:  # on the Agg canvas: no GUI, no pyplot state (as ectskin.viz draws)
        fig = Figure(figsize=(8.0, 0.42 * max(len(rows), 1) + 2.0))
        FigureCanvasAgg(fig)
        axes = fig.add_subplot()
    else:
        fig = axes.figure
    styles = (
        ("paper", "paper recipe (quick)", "o", "C0", -0.2),
        ("robust", "robust recipe", "s", "C2", 0.0),
        ("baseline_accuracy", "strongest baseline", "^", "C3", 0.2),
    )
    for key, label, marker, colour, dy in styles:
        for i, row in enumerate(rows):
            values = 100 * np.array([c[key] for c in summary[row].values()])
            y = len(rows) - 1 - i + dy
            axes.scatter(values, np.full(values.size, y), s=14, marker=marker, color=colour,
                         alpha=0.45, linewidths=0)
            axes.scatter([values.mean()], [y], s=60, marker=marker, color=colour,
                         label=label if i == 0 else None, edgecolors="k", linewidths=0.5)
    axes.axvline(100 * PAPER_ACCURACY, color="0.3", ls="--", lw=1, label="paper 99.88 %")
    axes.set_yticks(range(len(rows)), rows[::-1])
    axes.set_xlabel("test accuracy (%)")
    axes.set_title("Touch accuracy per reading of the experiment (small: seeds; large: mean)")
    axes.grid(axis="x", alpha=0.3)
    if rows:
        axes.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=4, fontsize=8)
    fig.tight_layout()
    return fig


def write_table(
    out: str | Path, seeds: Sequence[int] | None = None
) -> tuple[Path, Path | None]:
    """Write ``out/reading_ablation.md`` (and ``.png`` when there is a result) from the result
    files there (only ``seeds`` if given). Returns (table path, figure path or None)."""
    out = Path(out)
    summary = summarise(out)
    if seeds is not None:
        keep = set(seeds)
        summary = {r: {s: c for s, c in cells.items() if s in keep} for r, cells in summary.items()}
        summary = {r: cells for r, cells in summary.items() if cells}
    text = "# Reading ablation\n\n" + (
        table_markdown(summary) if summary else "No results yet.\n"
    )
    table = write_text_atomic(out / TABLE_FILE, text)
    write_json_atomic(out / SUMMARY_FILE, summary_document(summary))
    if not summary:
        return table, None
    figure = save_figure_atomic(plot_reading(summary), out / FIGURE_FILE, dpi=120)
    return table, figure


def summary_document(summary: dict[str, dict[int, dict[str, Any]]]) -> dict[str, Any]:
    """The summary as a JSON document: per row its description, the fields it changes and per
    seed the paper recipe's, the robust recipe's and the strongest baseline's test accuracy and
    the epoch the paper recipe kept (what ``ectskin.report.reading`` reads)."""
    import datetime

    by_name = {r.name: r for r in ROWS}
    rows: dict[str, Any] = {}
    for name, cells in summary.items():
        row = by_name.get(name)
        rows[name] = {
            "what": row.what if row else "",
            "changes": dict(row.changes) if row else {},
            "split": row.split if row else "trial",
            "seeds": {
                str(s): {k: c[k] for k in ("paper", "robust", "baseline", "baseline_accuracy",
                                           "epoch", "epochs")}
                for s, c in cells.items()
            },
        }
    return {
        "format": SUMMARY_FORMAT,
        "version": 1,
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "paper_accuracy": PAPER_ACCURACY,
        "rows": rows,
    }
