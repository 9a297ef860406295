"""Score a set of layouts (``ectskin design score``): one task per layout on Dask, resumable.

Layout ``name`` is scored into ``OUT/layouts/<name>/`` (:func:`~ectskin.design.score.score_layout`).
Before anything is submitted, each layout whose ``score.json`` matches its layout and settings
is taken as it is; ``OUT/design.json`` is rewritten (atomically) after every finished layout, so
a sweep killed in the middle resumes with the layouts still missing. The paper's layout is
always scored too, named ``paper``.

With an :class:`~ectskin.design.information.InformationConfig` each layout is also given its
information score (``information.json`` beside ``score.json``, in the same task, after the
trained score): its summary keys (``bound_mm_mean``, ``bound_mm_p95``,
``force_observable_share``, ``ambiguity_sigma``, ``wire_length_mm``) join the layout's entry.

With ``seeds`` every layout is trained and evaluated once per seed (the protocol's, the split's
and the models' seed) into ``OUT/layouts/<name>/seed-<k>/``, the paper's layout with the same
seeds (so on the same test touches): the entry's trained metrics are their means over the seeds,
``trained`` holds each metric's values, seeds, mean and 95 % t-interval, and ``vs_paper`` the
paired comparison with the paper's layout (:mod:`ectskin.design.stats`).

With the field reading (``ScoreConfig.response="field"``) the response fields of every layout
to score are built first, each once whatever the number of seeds, on the sweep's own cluster
(:func:`build_fields_first`); the tasks then only read them, and ``design.json``'s ``fields``
says what the build did.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin._files import write_json_atomic
from ectskin.design.cluster import iter_jobs, open_runner
from ectskin.design.family import ManufacturingRules, check_manufacturable
from ectskin.design.information import (
    SUMMARY_KEYS,
    InformationConfig,
    finished_information,
    information_layout,
)
from ectskin.design.report import write_report
from ectskin.design.score import (
    ScoreConfig,
    finished_score,
    score_layout,
    score_to_dict,
    scored_layout,
)
from ectskin.design.score_field import build_score_fields, field_specs
from ectskin.design.stats import METRICS, aggregate, compare_with, goal_layouts, rank_agreement
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
    information: InformationConfig | None = None,
    information_fn: Callable = information_layout,
    seeds: Sequence[int] | None = None,
) -> dict[str, Any]:
    """Score ``named`` layouts (``(name, layout)``; the paper's is added as ``paper``) into
    ``out`` and write ``design.json`` (and ``design.md``/``design.html`` with ``report``).

    Every layout is checked against ``rules`` before any work starts. Returns the design dict.
    ``score_fn`` is the per-layout scorer (a test hook; it must be importable by the workers);
    ``information``: also the information score of each layout (``information_fn``, a test
    hook like ``score_fn``), None: not. ``seeds``: train and evaluate with each of these seeds
    (module docstring), None: once with ``config.seed``.
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
    if seeds is not None:
        seeded_design, seeded_scores = _score_seeds(
            named, out, config, list(seeds), n_workers, scheduler, score_fn, information,
            information_fn,
        )
        if report:
            write_report(out, seeded_design, seeded_scores)
        return seeded_design
    scores: dict[str, dict] = {}
    todo: list[tuple] = []
    for name, layout in named:
        done = finished_score(layout_dir(out, name), layout, config)
        if done is not None and information is not None:
            info = finished_information(layout_dir(out, name), layout, information)
            done = None if info is None else with_information(done, info)
        if done is not None:
            scores[name] = done
        elif information is None:
            todo.append((layout, layout_dir(out, name), config))
        else:
            todo.append(
                (layout, layout_dir(out, name), config, information, score_fn, information_fn)
            )
    task = score_fn if information is None else score_and_inform
    extra = None if information is None else {"information_settings": information.to_dict()}
    log.info("%d layout(s) finished before, %d to score", len(scores), len(todo))
    names = {str(layout_dir(out, n)): n for n, _ in named}
    t0 = time.perf_counter()
    with open_runner(n_workers, scheduler) as runner:
        built = build_fields_first([job[0] for job in todo], config, runner)
        if built is not None:
            extra = {**(extra or {}), "fields": built}
        for job, score in runner.stream(task, iter_jobs(todo)):
            scores[names[str(job[1])]] = score
            write_design(out, named, scores, config, runner, time.perf_counter() - t0, extra)
        design = write_design(
            out, named, scores, config, runner, time.perf_counter() - t0, extra
        )
    if report:
        write_report(out, design, scores)
    return design


def build_fields_first(
    layouts: Sequence[SensorLayout], config: ScoreConfig, runner
) -> dict[str, Any] | None:
    """With the field reading: the response fields of every layout in ``layouts`` (each once,
    however many of its seeds are to score) built before the scoring tasks, on the runner's
    cluster (in this process for a serial runner), so that the tasks only read them; what the
    build did (``seconds``, chunks ``solved`` / ``cached``, ``fields``). None with the solve
    reading."""
    if config.response != "field":
        return None
    specs, seen = [], set()
    for layout in layouts:
        for spec in field_specs(config.protocol, scored_layout(layout, config), config.grid):
            if spec.key() not in seen:
                seen.add(spec.key())
                specs.append(spec)
    serial = runner.address == "serial"
    log.info("response fields of %d layout(s) to score: %d field(s)",
             len({layout.to_json() for layout in layouts}), len(specs))
    report = build_score_fields(
        specs,
        config.field_cache,
        scheduler=None if serial else runner.address,
        workers=0 if serial else None,
    )
    return {
        "seconds": report.seconds,
        "solved": report.solved,
        "cached": report.cached,
        "fields": len(specs),
    }


def seeded(config: ScoreConfig, seed: int) -> ScoreConfig:
    """``config`` with ``seed`` for the split, the models and the protocol's draws."""
    return replace(config, seed=seed, protocol=replace(config.protocol, seed=seed))


def run_job(fn: Callable, layout: SensorLayout, out_dir: Path, config: Any) -> dict:
    """One task of a seeded sweep: ``fn(layout, out_dir, config)``."""
    return fn(layout, out_dir, config)


def _score_seeds(
    named, out, config, seeds, n_workers, scheduler, score_fn, information, information_fn
):
    """The seeded sweep: one task per (layout, seed) and one per layout's information score;
    then the entries (module docstring). Returns (design, scores)."""
    if len(seeds) < 1 or len(set(seeds)) != len(seeds):
        raise EctskinError(f"--seeds: expected one or more distinct seeds, got {seeds!r}")
    jobs, where = [], {}
    per_seed: dict[str, dict[int, dict]] = {n: {} for n, _ in named}
    infos: dict[str, dict] = {}
    for name, layout in named:
        for k in seeds:
            d, cfg = layout_dir(out, name) / f"seed-{k}", seeded(config, k)
            done = finished_score(d, layout, cfg)
            if done is None:
                jobs.append((score_fn, layout, d, cfg))
                where[str(d)] = (name, k)
            else:
                per_seed[name][k] = done
        if information is not None:
            d = layout_dir(out, name)
            done = finished_information(d, layout, information)
            if done is None:
                jobs.append((information_fn, layout, d, information))
                where[str(d)] = (name, None)
            else:
                infos[name] = done
    log.info("%d task(s) to run over %d layout(s) and %d seed(s)", len(jobs), len(named), len(seeds))
    t0 = time.perf_counter()
    extra: dict[str, Any] = {"seeds": seeds}
    with open_runner(n_workers, scheduler) as runner:
        built = build_fields_first(
            [job[1] for job in jobs if job[0] is score_fn], config, runner
        )
        if built is not None:
            extra["fields"] = built
        for job, score in runner.stream(run_job, iter_jobs(jobs)):
            name, k = where[str(job[2])]
            if k is None:
                infos[name] = score
            else:
                per_seed[name][k] = score
        ref = per_seed.get(PAPER)
        scores = {}
        for name, _ in named:
            entry = merge_seeds(per_seed[name], None if name == PAPER else ref)
            scores[name] = entry if name not in infos else with_information(entry, infos[name])
        if information is not None:
            extra["information_settings"] = information.to_dict()
        design = write_design(
            out, named, scores, config, runner, time.perf_counter() - t0, extra
        )
    return design, scores


def merge_seeds(
    per_seed: Mapping[int, Mapping[str, Any]], paper: Mapping[int, Mapping[str, Any]] | None
) -> dict[str, Any]:
    """One layout's score over seeds: the first seed's score (its maps, its sensor metrics,
    which do not depend on the seed) with each trained metric and the per-face error replaced by
    their means over the seeds; ``trained`` (:func:`~ectskin.design.stats.aggregate`), ``vs_paper``
    (:func:`~ectskin.design.stats.compare_with`, when ``paper`` is given) and the total time."""
    first = per_seed[min(per_seed)]
    agg = aggregate(per_seed)
    out = {**first, **{m: agg[m]["mean"] for m in METRICS if m in agg}, "trained": agg}
    faces = [s.get("loc_mm_per_face") or {} for s in per_seed.values()]
    out["loc_mm_per_face"] = {
        f: sum(x[f] for x in faces) / len(faces)
        for f in faces[0]
        if all(x.get(f) is not None for x in faces)
    }
    out["seconds"] = {"total": sum(s["seconds"]["total"] for s in per_seed.values())}
    if paper is not None:
        out["vs_paper"] = compare_with(per_seed, paper)
    return out


def with_information(score: Mapping[str, Any], info: Mapping[str, Any]) -> dict[str, Any]:
    """A trained score with an information score's summary (and its maps and ambiguity)."""
    return {
        **score,
        **{k: info[k] for k in SUMMARY_KEYS},
        "ambiguity": info["ambiguity"],
        "maps": info["maps"],
        "information_seconds": info["information_seconds"],
        "information_cpu_seconds": info.get("information_cpu_seconds"),
    }


def score_and_inform(layout, out_dir, config, information, score_fn, information_fn) -> dict:
    """One layout's task with the information score: the trained score (which starts an
    unfinished folder over), then the information score, merged (:func:`with_information`)."""
    score = score_fn(layout, out_dir, config)
    return with_information(score, information_fn(layout, out_dir, information))


def _entry(score: Mapping[str, Any]) -> dict[str, Any]:
    """A trained score's ``design.json`` entry (with the information summary where it has one)."""
    return score_to_dict({k: v for k, v in score.items() if k != "maps"})


def write_design(
    out, named, scores, config, runner, seconds, extra=None, to_entry: Callable = _entry
) -> dict[str, Any]:
    """Write ``design.json``: the settings, the engine and one entry per scored layout
    (``to_entry`` of its score, with its name and folder); with both scores on 3 or more
    layouts the ``rank_agreement`` of the worst-case bound
    (:func:`~ectskin.design.stats.rank_agreement`; ``rank_agreement_fit``,
    ``rank_agreement_fit_median``: of the fit error's p95 and median), with paired
    comparisons the ``goal`` (:func:`~ectskin.design.stats.goal_layouts`)."""
    entries = []
    for name, _ in named:
        if name in scores:
            entry = to_entry(scores[name])
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
    agreement = rank_agreement(entries)
    if agreement is not None:
        design["rank_agreement"] = agreement
    for name, key in (("rank_agreement_fit", "fit_error_mm_p95"),
                      ("rank_agreement_fit_median", "fit_error_mm_median")):
        fit_agreement = rank_agreement(entries, key=key)
        if fit_agreement is not None:
            design[name] = fit_agreement
    if any("vs_paper" in e for e in entries):
        design["goal"] = goal_layouts(entries)
    write_json_atomic(Path(out) / DESIGN_FILE, design)
    return design
