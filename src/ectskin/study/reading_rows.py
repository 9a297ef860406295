"""The rows of the reading ablation (:mod:`ectskin.study.reading`) and its result files.

:data:`ROWS`: each row the one-point reading (:data:`ONE_POINT`: ``Protocol(seed=s)`` with one
point held per trial, the twin's default until the ablation chose the sliding reading; the
``sliding`` row is today's default ``Protocol(seed=s)``) with one choice of the reading changed
(:class:`Row`); :data:`RUN_ORDER`: the order a seed's rows run in. :func:`cell_settings`: what a
cell's numbers depend on, stored in its result file ``OUT/results/<row>_s<seed>.json``
(:func:`result_path`, read back by :func:`read_result`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError
from ectskin._files import read_json, to_jsonable
from ectskin.twin.protocol import Protocol

FORMAT = "ectskin.study.reading"
VERSION = 1
RESULTS = "results"
WORK = "work"
#: the paper's touch split (trials: train, val, test), which every row keeps
#: (ectskin.learn.splits.TOUCH_SPLIT, what the trainings use; a test keeps the two equal)
SPLIT_COUNTS = (125, 32, 32)
#: what the ablation's base reading changes in the default protocol: one point held per trial
#: (the twin's default reading when the ablation was made; docs/paper-reading.md)
ONE_POINT: dict[str, Any] = {"touch_dwells": 1, "dwell_slide_s": 0.0}


@dataclass(frozen=True)
class Row:
    """One row of the ablation: ``changes`` to the one-point protocol (field → value; the readout's
    fields as ``readout.<name>``), on the ``split`` ("trial": the reproduction's trial-exclusive
    split; "frame": the frame-level diagnostic), with a short description."""

    name: str
    what: str
    changes: Mapping[str, Any] = field(default_factory=dict)
    split: str = "trial"

    def protocol(self, seed: int, base: Protocol | None = None) -> Protocol:
        """The one-point ``Protocol(seed=seed)`` (:data:`ONE_POINT`; or ``base`` with ``seed``)
        with this row's changes."""
        base = replace(Protocol(seed=seed), **ONE_POINT) if base is None else replace(base, seed=seed)
        top = {k: v for k, v in self.changes.items() if "." not in k}
        readout = {k.split(".", 1)[1]: v for k, v in self.changes.items() if k.startswith("readout.")}
        if readout:
            top["readout"] = replace(base.readout, **readout)
        return replace(base, **top)

    @property
    def data_name(self) -> str:
        """The name of this row's simulation: rows of the same protocol share one."""
        return "one_point" if not self.changes else self.name


#: the rows, in the order the table lists them (they run in :data:`RUN_ORDER`)
ROWS: tuple[Row, ...] = (
    Row("one_point", "the earlier reading: 1 point per trial held 30 s, force 0.3-2 N, pad "
        "slide 0.5 mm, hand up to 2 N, readout noise x1, people's fingers differ"),
    Row("dwells_2", "2 points per trial (the finger moves to a new point after 15 s)",
        {"touch_dwells": 2}),
    Row("dwells_4", "4 points per trial", {"touch_dwells": 4}),
    Row("dwells_8", "8 points per trial", {"touch_dwells": 8}),
    Row("sliding", "8 points per trial, the finger sliding in contact from each to the next "
        "over the whole dwell (today's default reading)",
        {"touch_dwells": 8, "dwell_slide_s": None}),
    Row("force_narrow", "finger force 0.3-1 N", {"force_range_n": (0.3, 1.0)}),
    Row("force_wide", "finger force 0.3-4 N", {"force_range_n": (0.3, 4.0)}),
    Row("no_pad_slide", "the pad does not roll or slide (slide_mm 0)", {"slide_mm": 0.0}),
    Row("pad_slide_2mm", "the pad rolls and slides 2 mm (slide_mm 2)", {"slide_mm": 2.0}),
    Row("hand_off", "no handling hand (push_max_n 0)", {"push_max_n": 0.0}),
    Row("noise_x0", "a noiseless readout (noise_scale 0)", {"readout.noise_scale": 0.0}),
    Row("noise_x3", "three times the readout noise (noise_scale 3)", {"readout.noise_scale": 3.0}),
    Row("fingers_same", "one finger for every trial (finger_variability off)",
        {"finger_variability": False}),
    Row("random_split", "diagnostic: the one-point data split by frame at random (leaks trials)",
        split="frame"),
)
ROW_NAMES = tuple(r.name for r in ROWS)
#: the order the rows of one seed run in: the diagnostic beside one_point (it reads the same
#: data), then the cheaper simulations, the 8-point rows last (8 and about 15 readout models per
#: touch trial instead of 1), so a study stopped early has the most rows
RUN_ORDER = (
    "one_point", "random_split", "dwells_4", "hand_off", "fingers_same", "noise_x0", "dwells_2",
    "force_narrow", "force_wide", "no_pad_slide", "pad_slide_2mm", "noise_x3", "dwells_8",
    "sliding",
)


def get_rows(names: Sequence[str] | None = None) -> list[Row]:
    """The rows named, all for None, in :data:`RUN_ORDER`; an unknown name is an error."""
    wanted = set(ROW_NAMES if names is None else names)
    unknown = sorted(wanted - set(ROW_NAMES))
    if unknown:
        raise EctskinError(
            f"study reading: unknown row(s) {unknown}; rows: {', '.join(ROW_NAMES)}"
        )
    by_name = {r.name: r for r in ROWS}
    return [by_name[n] for n in RUN_ORDER if n in wanted]


def cell_settings(row: Row, seed: int, base: Protocol | None = None) -> dict[str, Any]:
    """Everything a cell's numbers depend on (not the worker count: the simulation does not),
    as stored in its result file."""
    from ectskin.study.reading_eval import THREADS, recipes

    return to_jsonable(
        {
            "format": FORMAT,
            "version": VERSION,
            "row": row.name,
            "seed": seed,
            "changes": dict(row.changes),
            "split": row.split,
            "split_counts": SPLIT_COUNTS,
            "protocol": row.protocol(seed, base).to_dict(),
            "recipes": recipes(),
            "threads": THREADS,
        }
    )


def result_path(out: Path, row: Row | str, seed: int) -> Path:
    name = row if isinstance(row, str) else row.name
    return Path(out) / RESULTS / f"{name}_s{seed}.json"


def read_result(path: Path) -> dict[str, Any] | None:
    """A cell's result file, or None where it is missing or not one."""
    if not path.exists():
        return None
    try:
        doc = read_json(path, "reading ablation result")
    except EctskinError:
        return None
    if not isinstance(doc, dict) or doc.get("settings", {}).get("format") != FORMAT:
        return None
    return doc

