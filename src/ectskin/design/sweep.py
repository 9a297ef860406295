"""Score a set of layouts (``ectskin design score``): one task per layout on Dask, resumable.

Layout ``name`` is scored into ``OUT/layouts/<name>/`` (:func:`~ectskin.design.score.score_layout`).
Before anything is submitted, each layout whose ``score.json`` matches its layout and settings
is taken as it is; ``OUT/design.json`` is rewritten (atomically) after every finished layout, so
a sweep killed in the middle resumes with the layouts still missing. The paper's layout is
always scored too, named ``paper``.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin._files import write_json_atomic
from ectskin.design.cluster import iter_jobs, open_runner
from ectskin.design.family import ManufacturingRules, check_manufacturable
from ectskin.design.report import write_report
from ectskin.design.score import ScoreConfig, finished_score, score_layout, score_to_dict
from ectskin.layout import SensorLayout, default_layout

log = logging.getLogger(__name__)

DESIGN_FILE = "design.json"
PAPER = "paper"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def layout_dir(out: str | Path, name: str) -> Path:
    return Path(out) / "layouts" / name


def check_names(named: Sequence[tuple[str, SensorLayout]]) -> None:
    """Names are unique folder names (letters, digits, ``._-``, at most 64)."""
    seen: set[str] = set()
    for name, layout in named:
        where = layout.source or f"layout {layout.name!r}"
        if not _NAME.match(name):
            raise EctskinError(
                f"{where}: design name {name!r} must be 1-64 letters, digits, '.', '_' or '-' "
                f"(it names the layout's folder)"
            )
        if name in seen:
            raise EctskinError(f"{where}: design name {name!r} is used twice (rename the file)")
        seen.add(name)


def score_layouts(
    named: Sequence[tuple[str, SensorLayout]],
    out: str | Path,
    config: ScoreConfig | None = None,
    *,
    n_workers: int = 2,
    scheduler: str | None = None,
    rules: ManufacturingRules | None = None,
    include_paper: bool = True,
    score_fn: Callable[[SensorLayout, Path, ScoreConfig], dict] = score_layout,
    report: bool = True,
) -> dict[str, Any]:
    """Score ``named`` layouts (``(name, layout)``; the paper's is added as ``paper``) into
    ``out`` and write ``design.json`` (and ``design.md``/``design.html`` with ``report``).

    Every layout is checked against ``rules`` before any work starts. Returns the design dict.
    ``score_fn`` is the per-layout scorer (a test hook; it must be importable by the workers).
    """
    config = config or ScoreConfig()
    named = list(named)
    if include_paper and PAPER not in [n for n, _ in named]:
        named.insert(0, (PAPER, default_layout()))
    check_names(named)
    for _, layout in named:
        check_manufacturable(layout, rules)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scores: dict[str, dict] = {}
    todo = []
    for name, layout in named:
        done = finished_score(layout_dir(out, name), layout, config)
        if done is not None:
            scores[name] = done
        else:
            todo.append((layout, layout_dir(out, name), config))
    log.info("%d layout(s) finished before, %d to score", len(scores), len(todo))
    names = {str(layout_dir(out, n)): n for n, _ in named}
    t0 = time.perf_counter()
    with open_runner(n_workers, scheduler) as runner:
        for job, score in runner.stream(score_fn, iter_jobs(todo)):
            scores[names[str(job[1])]] = score
            write_design(out, named, scores, config, runner, time.perf_counter() - t0)
        design = write_design(out, named, scores, config, runner, time.perf_counter() - t0)
    if report:
        write_report(out, design, scores)
    return design


def write_design(out, named, scores, config, runner, seconds, extra=None) -> dict[str, Any]:
    entries = []
    for name, _ in named:
        if name in scores:
            entry = score_to_dict(scores[name])
            entry["name"] = name
            entry["layout_name"] = scores[name]["name"]
            entry["folder"] = f"layouts/{name}"
            entries.append(entry)
    design = {
        "ectskin_version": __version__,
        "settings": config.to_dict(),
        "engine": {"address": runner.address, "n_workers": runner.n_workers},
        "sweep_seconds": seconds,
        "complete": len(entries) == len(named),
        "layouts": entries,
        **(extra or {}),
    }
    write_json_atomic(Path(out) / DESIGN_FILE, design)
    return design
