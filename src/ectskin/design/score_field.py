"""The trained score's dense data read from response fields (``ScoreConfig.response="field"``).

With the solve reading (:func:`~ectskin.design.score.design_protocol`) every dwell of a touch
trial costs a dozen method-of-moments solves, so the design protocol touches about a hundred
distinct points in all: too few to train on, and the trained score's seed-to-seed spread is
larger than the differences between layouts. Read from the response fields of the protocol's
inflation states (docs/field.md), a finger that moves to a new point every :data:`DWELL_S`
costs nothing per point, so the field protocol (:func:`dense_protocol`) has
:data:`FIELD_TOUCH_TRIALS` touch trials of :data:`FIELD_DURATION_S` per state (twice the solve
protocol's trials, five times as long; 30 points a trial, about 2 900 over the 8 states) while
the per-trial solves (the body under the hand, the finger's anchors, the lifts) stay about a
dozen. More trials rather than only longer ones: a trial draws its finger, hand and force walk,
and the test split is a set of whole trials, so its independent draws grow with the trials.

A field depends on the layout (with the scoring regions, which the simulation checks it
against), the inflation state, the finger and force range of the protocol and the grid, **not
on the seed**: the seeds of one layout read the same fields. They are cached by their key in
the field cache (:func:`ectskin.pipeline.field.field_cache_dir`); a seeded sweep builds the
fields of every layout before the seeds' tasks, on its own cluster
(:func:`ectskin.design.sweep.score_layouts`), and :func:`score_fields` reads them (or builds
the missing ones in the calling process, one after another).
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout
from ectskin.pipeline.field import field_cache_dir, protocol_field_specs
from ectskin.twin import Protocol
from ectskin.twin.field_build import BuildReport, build_chunks, field_dir
from ectskin.twin.field_spec import FIELD_GRIDS, FieldGrid, FieldSpec
from ectskin.twin.sensor import Discretisation

#: the field protocol's touch trials per state and their length (s), and how long the finger
#: stays at each point (s; the reproduction's contact experiment's) and the share of that
#: spent sliding, in contact, to the next point
FIELD_TOUCH_TRIALS = 12
FIELD_DURATION_S = 15.0
DWELL_S = 0.5
SLIDE = 1 / 3
#: the grid of the score's fields by default (:data:`~ectskin.twin.field_spec.FIELD_GRIDS`)
DEFAULT_GRID = "quick"


def dense_protocol(protocol: Protocol, dwell_s: float = DWELL_S) -> Protocol:
    """``protocol`` read from response fields, its finger at a new point every ``dwell_s``
    (at least one point a trial, at most one a frame), sliding there for :data:`SLIDE` of it."""
    if not (isinstance(protocol, Protocol)):
        raise EctskinError(f"dense_protocol: expected a Protocol, got {type(protocol).__name__}")
    if not (isinstance(dwell_s, int | float) and dwell_s > 0):
        raise EctskinError(f"dense_protocol: dwell_s must be a number > 0 (s), got {dwell_s!r}")
    dwells = max(1, min(protocol.n_frames, int(round(protocol.duration_s / dwell_s))))
    return replace(
        protocol,
        response="field",
        touch_dwells=dwells,
        dwell_slide_s=SLIDE * protocol.duration_s / dwells,
    )


def resolve_grid(grid: str | FieldGrid) -> FieldGrid:
    """A field grid by name (:data:`~ectskin.twin.field_spec.FIELD_GRIDS`) or as it is."""
    if isinstance(grid, FieldGrid):
        return grid
    if not isinstance(grid, str):
        raise EctskinError(
            f"score config: field_grid must be a grid name ({', '.join(FIELD_GRIDS)}) or a "
            f"FieldGrid, got {type(grid).__name__}"
        )
    check_option("field_grid", grid, tuple(FIELD_GRIDS), source="score config")
    return FIELD_GRIDS[grid]


def grid_to_dict(grid: FieldGrid) -> dict[str, Any]:
    return asdict(grid)


def grid_from_dict(d: dict[str, Any]) -> FieldGrid:
    """The inverse of :func:`grid_to_dict` (lists back to tuples)."""
    fine = d.get("fine_spacing_mm")
    return FieldGrid(
        spacing_mm=(float(d["spacing_mm"][0]), float(d["spacing_mm"][1])),
        force_nodes=int(d["force_nodes"]),
        height_nodes=int(d["height_nodes"]),
        discretisation=Discretisation(**d["discretisation"]),
        fine_spacing_mm=None if fine is None else (float(fine[0]), float(fine[1])),
        wall_band_mm=float(d["wall_band_mm"]),
        end_band_mm=float(d["end_band_mm"]),
    )


def field_specs(protocol: Protocol, layout: SensorLayout, grid: FieldGrid) -> list[FieldSpec]:
    """One field spec per inflation state of ``protocol`` on ``layout`` (the scored layout,
    with its scoring regions) and the default body, on ``grid``
    (:func:`ectskin.pipeline.field.protocol_field_specs`)."""
    return protocol_field_specs(protocol, layout, grid)


def build_score_fields(
    specs: list[FieldSpec],
    cache_dir: str | os.PathLike | None,
    *,
    scheduler: str | None = None,
    workers: int | None = 0,
) -> BuildReport:
    """Solve the chunks of ``specs``' fields not yet in the cache (``cache_dir``, else
    :func:`~ectskin.pipeline.field.field_cache_dir`): here (``workers=0``), on a new
    LocalCluster of ``workers``, or on the scheduler at ``scheduler``."""
    report = build_chunks(
        specs, field_cache_dir(cache_dir), scheduler=scheduler, workers=workers, progress=False
    )
    if not report.complete:  # (cannot happen without max_chunks)
        raise EctskinError("response fields incomplete after the build; build them again")
    return report


def score_fields(
    protocol: Protocol, layout: SensorLayout, grid: FieldGrid, cache_dir: str | os.PathLike | None
) -> tuple[dict[tuple[float, ...], Path], dict[str, Any]]:
    """The cache folder of the field of every state of ``protocol`` on ``layout`` (state →
    folder, what :func:`~ectskin.twin.simulate_experiment` reads), the missing ones built in
    this process; and what that took (``seconds``, chunks ``solved`` and ``cached``)."""
    t0 = time.perf_counter()
    specs = field_specs(protocol, layout, grid)
    report = build_score_fields(specs, cache_dir)
    root = field_cache_dir(cache_dir)
    dirs = {s.inflation_ml: field_dir(s, root) for s in specs}
    info = {
        "seconds": time.perf_counter() - t0,
        "solved": report.solved,
        "cached": report.cached,
        "keys": [s.key() for s in specs],
    }
    return dirs, info


__all__ = [
    "DEFAULT_GRID",
    "DWELL_S",
    "FIELD_DURATION_S",
    "FIELD_TOUCH_TRIALS",
    "build_score_fields",
    "dense_protocol",
    "field_specs",
    "grid_from_dict",
    "grid_to_dict",
    "resolve_grid",
    "score_fields",
]
