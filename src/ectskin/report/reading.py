"""The report's lead paragraph on touch: what the paper's recipe gets on this run's reading of the
paper's experiment, and which choices of that reading move it, with the reading ablation's numbers.

The ablation (``ectskin study reading``, ``docs/paper-reading.md``) is measured once, not per
run: its summary (``reading_ablation.json``, written by ``ectskin study reading --table-only``)
ships with the package as ``ectskin/report/data/reading_ablation.json`` and says when it was made.
:func:`reading_paragraph` sets this run's accuracy beside it; a run whose metrics hold no
protocol (a recording, not the twin) gets its accuracy without the reading's description.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError
from ectskin.report.tables import strongest_baseline
from ectskin.report.wording import baseline_name, lookup, pct

#: the ablation summary's format (ectskin.study.reading_table.SUMMARY_FORMAT)
SUMMARY_FORMAT = "ectskin.study.reading.summary"
#: the ablation's base row: one point held per trial, the twin's reading before the ablation
BASE_ROW = "one_point"


def load_ablation(path: str | Path | None = None) -> dict[str, Any]:
    """The reading ablation's summary: ``path``, or the one shipped with the package. A file of
    another format is an error that names it."""
    if path is None:
        text = resources.files("ectskin.report").joinpath("data/reading_ablation.json").read_text()
        where = "ectskin/report/data/reading_ablation.json"
    else:
        text, where = Path(path).read_text(), str(path)
    doc = json.loads(text)
    if not isinstance(doc, dict) or doc.get("format") != SUMMARY_FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise EctskinError(
            f"{where}: format: expected {SUMMARY_FORMAT!r} (ectskin study reading --table-only), "
            f"found {found!r}"
        )
    return doc


def reading_description(protocol: Mapping[str, Any]) -> str:
    """The reading of the paper's touch trials that ``protocol`` (a ``Protocol.to_dict()``)
    simulates, in words."""
    dwells = int(protocol.get("touch_dwells", 1))
    duration = float(protocol.get("duration_s", 30.0))
    slide = protocol.get("dwell_slide_s", 0.0)
    if dwells <= 1:
        return f"one point per trial, held for the whole {duration:g}-s trial"
    dwell = duration / dwells
    if slide is None or float(slide) >= dwell - 1e-9:
        return (f"{dwells} points per trial, the finger sliding in contact from each to the next "
                f"over the whole {duration:g}-s trial")
    if float(slide) > 0:
        return (f"{dwells} points per trial, {dwell:g} s each, the finger sliding to the next "
                f"over the last {float(slide):g} s of each")
    return f"{dwells} points per trial, the finger moving to the next every {dwell:g} s"


def _mean(cells: Mapping[str, Any], key: str = "paper") -> float:
    return sum(float(c[key]) for c in cells.values()) / len(cells)


def ablation_sentences(ablation: Mapping[str, Any]) -> str:
    """What the ablation measured, in sentences: the paper recipe's mean accuracy per row, the
    rows above the base row on every seed both have, and the frame-split diagnostic."""
    rows: Mapping[str, Any] = ablation.get("rows", {})
    trial_rows = {k: r for k, r in rows.items() if r.get("split", "trial") == "trial" and r["seeds"]}
    base = trial_rows.get(BASE_ROW)
    parts = [f"`{k}` {pct(_mean(r['seeds']))} ({len(r['seeds'])} seed"
             f"{'s' if len(r['seeds']) != 1 else ''})" for k, r in trial_rows.items()]
    date = str(ablation.get("created_utc", ""))[:10]
    text = (
        "Which choices of the reading move it: the reading ablation (`ectskin study reading`, "
        f"docs/paper-reading.md{', summary of ' + date if date else ''}) changes one at a time "
        "and trains the paper's recipe on each; its mean test accuracy per row: "
        + "; ".join(parts) + "."
    )
    if base is not None:
        above, mixed = [], []
        for k, r in trial_rows.items():
            shared = sorted(set(r["seeds"]) & set(base["seeds"]))
            if k == BASE_ROW or not shared:
                continue
            gain = [100 * (float(r["seeds"][s]["paper"]) - float(base["seeds"][s]["paper"]))
                    for s in shared]
            if min(gain) > 0:
                above.append(f"`{k}` {min(gain):+.2f} to {max(gain):+.2f}")
            else:
                mixed.append(f"`{k}` {min(gain):+.2f} to {max(gain):+.2f}")
        spread = [float(c["paper"]) for c in base["seeds"].values()]
        if above:
            text += (" Above the one-point reading on every seed they share (the least and the "
                     "largest gain, points): " + "; ".join(above) + ".")
        if mixed:
            text += (" Not on every seed: " + "; ".join(mixed) + f" (the one-point reading "
                     f"alone spans {pct(min(spread))}–{pct(max(spread))} over its seeds).")
    frame = [r for r in rows.values() if r.get("split") == "frame" and r["seeds"]]
    if frame:
        text += (f" Split by frame instead of by trial (which leaks trials into training) it "
                 f"reaches {pct(_mean(frame[0]['seeds']))}.")
    return text


def reading_paragraph(
    metrics: Mapping[str, Any], ablation: Mapping[str, Any] | None = None
) -> str | None:
    """The lead paragraph (module docstring); None when the run has no touch accuracy.
    ``ablation``: the ablation summary (default: the shipped one, :func:`load_ablation`)."""
    acc = lookup(metrics, "touch.accuracy")
    if acc is None:
        return None
    paper = 1.0 - 34 / 28800
    text = (
        f"Touch with the paper's recipe (the TouchMLP, trained as the paper trains it): "
        f"{pct(acc)} on this run's test trials, against the paper's {pct(paper)}"
    )
    best = strongest_baseline(metrics, "touch")
    if best is not None:
        text += (f"; the strongest baseline on the same test trials, '{baseline_name(best[0])}', "
                 f"gets {pct(best[1])}")
    text += "."
    protocol = lookup(metrics, "protocol")
    if not isinstance(protocol, Mapping):
        return text
    text += f" The twin reads the paper's touch trials as {reading_description(protocol)}."
    ablation = load_ablation() if ablation is None else ablation
    return text + " " + ablation_sentences(ablation)
