"""Search the layout family (``ectskin design search``): an Optuna multi-objective study of the
mean localisation error against the electrode count, layouts scored as Dask tasks.

Each trial samples a :class:`~ectskin.design.family.LayoutDesign` from a :class:`SearchSpace`
(wires per face, span, shortest and longest wire, length order, lead routing, width), builds
and checks it (:func:`~ectskin.design.family.build_layout`), and scores it
(:func:`~ectskin.design.score.score_layout`) into ``OUT/layouts/design-NNNN/`` whose
``layout.json`` every other command takes (``ectskin simulate --layout``). The paper's layout is
scored beside them as ``paper``.

The study lives in ``OUT/study.journal`` (Optuna's journal file storage): a rerun continues it.
Trials a killed run left running are scored again first (their finished layout folders are
reused), then new trials are asked until ``n_trials`` have finished. A rerun with other score
settings or another search space is refused (a new OUT is a new study).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import save_figure_atomic, to_jsonable
from ectskin.design.cluster import open_runner
from ectskin.design.family import (
    MAX_PAD_MM,
    MIN_PAD_MM,
    ORDERS,
    ROUTINGS,
    FaceDesign,
    LayoutDesign,
    ManufacturingRules,
    build_layout,
)
from ectskin.design.report import _close, pareto_front, plot_front, write_report
from ectskin.design.score import ScoreConfig, finished_score, score_layout
from ectskin.design.sweep import PAPER, layout_dir, write_design
from ectskin.layout import SensorLayout, default_layout

log = logging.getLogger(__name__)

STUDY_FILE = "study.journal"
STUDY_NAME = "ectskin-design"
SAMPLERS = ("tpe", "nsga2")
FRONT_FIGURE = "figures/front.png"


@dataclass(frozen=True)
class SearchSpace:
    """The family's ranges (mm). ``min_wires``..``max_wires`` wires per face; lengths of the
    shortest and longest wire within ``length_mm``; widths within ``width_mm``; every order and
    routing of :mod:`ectskin.design.family`."""

    min_wires: int = 2
    max_wires: int = 8
    length_mm: tuple[float, float] = (15.0, 105.0)
    width_mm: tuple[float, float] = (0.5, 2.0)

    def check(self, rules: ManufacturingRules, base: SensorLayout) -> None:
        """Refuse a space with no manufacturable layout, naming the field."""
        if not (isinstance(self.min_wires, int) and isinstance(self.max_wires, int)):
            raise EctskinError(f"search space: wires per face must be integers, got {self!r}")
        if self.min_wires < 2:
            raise EctskinError(
                f"search space: --min-wires must be >= 2 (a face needs two wires), got "
                f"{self.min_wires}"
            )
        if self.min_wires > self.max_wires:
            raise EctskinError(
                f"search space is empty: --min-wires {self.min_wires} > --max-wires "
                f"{self.max_wires}"
            )
        lo, hi = self.length_mm
        skin = min((s for s in base.skins), key=lambda s: s.v_mm[1] - s.v_mm[0])
        room = skin.v_mm[1] - skin.v_mm[0] - MAX_PAD_MM - rules.edge_margin_mm
        if not (0 < lo <= hi) or lo > room:
            raise EctskinError(
                f"search space is empty: --length-mm {lo:g}..{hi:g} must be 0 < low <= high "
                f"with low <= {room:g} mm (the skin's length above the pads)"
            )
        wlo, whi = self.width_mm
        if not (0 < wlo <= whi) or whi < rules.min_width_mm:
            raise EctskinError(
                f"search space is empty: --width-mm {wlo:g}..{whi:g} must be 0 < low <= high "
                f"with high >= the minimum width {rules.min_width_mm:g} mm"
            )
        width = min(s.u_mm[1] - s.u_mm[0] for s in base.skins)
        w = max(wlo, rules.min_width_mm)
        fits = [
            n
            for n in range(self.min_wires, self.max_wires + 1)
            if any(_span_range(n, r, w, width, rules) is not None for r in ROUTINGS)
        ]
        if not fits:
            raise EctskinError(
                f"search space is empty: {self.min_wires}..{self.max_wires} wires do not fit "
                f"across a {width:g} mm skin with {rules.min_spacing_mm:g} mm gaps and pads of "
                f"at least {MIN_PAD_MM:g} mm"
            )


def _pad(n: int, routing: str, span: float, width_skin: float, gap: float) -> float:
    if routing == "straight":
        return min(MAX_PAD_MM, span / (n - 1) - gap)
    return min(MAX_PAD_MM, (width_skin - (n + 1) * gap) / n)


def _span_range(n, routing, width, width_skin, rules) -> tuple[float, float] | None:
    """The spans (mm) for which ``n`` wires of ``width`` with ``routing`` fit (pads at least
    ``MIN_PAD_MM``, gaps ``rules.min_spacing_mm``, inside the skin), or None."""
    gap, m = rules.min_spacing_mm, rules.edge_margin_mm
    spans = np.linspace(0.0, width_skin, 2001)[1:]
    ok = []
    for s in spans:
        pad = _pad(n, routing, s, width_skin, gap)
        wire_ok = s / (n - 1) >= width + gap and s / 2 + width / 2 <= width_skin / 2 - m
        pad_ok = pad >= MIN_PAD_MM and (routing == "fan" or s / 2 + pad / 2 <= width_skin / 2 - m)
        ok.append(wire_ok and pad_ok)
    ok = np.asarray(ok)
    if not ok.any():
        return None
    return float(spans[ok].min()), float(spans[ok].max())


def sample_design(trial, space: SearchSpace, rules: ManufacturingRules, base: SensorLayout):
    """One :class:`LayoutDesign` from an Optuna ``trial`` (fixed parameter ranges, mapped onto
    the feasible range of each face so that most samples are manufacturable)."""
    faces = {}
    skins = {s.surface: s for s in base.skins}
    for face in ("front", "back"):
        sk = skins[face]
        w_skin = sk.u_mm[1] - sk.u_mm[0]
        n = trial.suggest_int(f"{face}_n_wires", space.min_wires, space.max_wires)
        routing = trial.suggest_categorical(f"{face}_routing", list(ROUTINGS))
        order = trial.suggest_categorical(f"{face}_order", list(ORDERS))
        width = trial.suggest_float(
            f"{face}_width_mm", max(space.width_mm[0], rules.min_width_mm), space.width_mm[1]
        )
        span_frac = trial.suggest_float(f"{face}_span", 0.0, 1.0)
        a = trial.suggest_float(f"{face}_length_a_mm", *space.length_mm)
        b = trial.suggest_float(f"{face}_length_b_mm", *space.length_mm)
        rng = _span_range(n, routing, width, w_skin, rules)
        if rng is None:
            raise EctskinError(
                f"{face}: {n} wires of {width:.2f} mm with {routing} routing do not fit"
            )
        pad = _pad(n, routing, rng[1], w_skin, rules.min_spacing_mm)
        room = sk.v_mm[1] - sk.v_mm[0] - max(pad, MIN_PAD_MM) - rules.edge_margin_mm
        lo, hi = sorted((min(a, room), min(b, room)))
        faces[face] = FaceDesign(
            n_wires=n,
            span_mm=round(rng[0] + span_frac * (rng[1] - rng[0]), 3),
            length_min_mm=round(lo, 2),
            length_max_mm=round(hi, 2),
            order=order,
            routing=routing,
            width_mm=round(width, 3),
        )
    return LayoutDesign(faces["front"], faces["back"])


def run_search(
    out: str | Path,
    *,
    n_trials: int = 6,
    space: SearchSpace | None = None,
    config: ScoreConfig | None = None,
    rules: ManufacturingRules | None = None,
    sampler: str = "tpe",
    seed: int = 0,
    n_workers: int = 2,
    scheduler: str | None = None,
    score_fn: Callable[[SensorLayout, Path, ScoreConfig], dict] = score_layout,
) -> dict[str, Any]:
    """Run (or continue) the study in ``out`` until ``n_trials`` trials have finished; write
    ``design.json``, the report and the front figure. Returns the design dict. ``score_fn`` is
    the per-layout scorer (a test hook; it must be importable by the workers)."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    space = space or SearchSpace()
    config = config or ScoreConfig()
    rules = rules or ManufacturingRules()
    check_option("sampler", sampler, SAMPLERS)
    if not isinstance(n_trials, int) or n_trials < 1:
        raise EctskinError(f"--trials must be an integer >= 1, got {n_trials!r}")
    base = default_layout()
    space.check(rules, base)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = JournalStorage(JournalFileBackend(str(out / STUDY_FILE)))
    samplers = {
        "tpe": lambda: optuna.samplers.TPESampler(seed=seed, n_startup_trials=4),
        "nsga2": lambda: optuna.samplers.NSGAIISampler(seed=seed, population_size=8),
    }
    study = optuna.create_study(
        study_name=STUDY_NAME,
        storage=storage,
        directions=["minimize", "minimize"],
        sampler=samplers[sampler](),
        load_if_exists=True,
    )
    settings = {
        "score": config.to_dict(),
        "space": asdict(space),
        "rules": asdict(rules),
        "sampler": sampler,
        "seed": seed,
    }
    settings = to_jsonable(settings)  # as the study's storage holds it
    old = study.user_attrs.get("settings")
    if old is None:
        study.set_user_attr("settings", settings)
    elif old != settings:
        changed = sorted(k for k in settings if settings[k] != old.get(k))
        raise EctskinError(
            f"{out / STUDY_FILE}: the study was started with other settings ({', '.join(changed)}); "
            f"continue it with the same options or choose a new OUT"
        )
    TrialState = optuna.trial.TrialState
    stale = [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.RUNNING]
    finished = sum(t.state in (TrialState.COMPLETE, TrialState.FAIL) for t in study.trials)
    log.info("study %s: %d finished, %d left running by an earlier run", out, finished, len(stale))
    names: dict[str, Any] = {}  # layout folder → ("paper", None) or (trial number)
    stale_jobs = []
    for t in stale:
        if "design" not in t.user_attrs:  # killed before its layout was recorded
            study.tell(t.number, state=TrialState.FAIL)
            continue
        design = LayoutDesign.from_dict(t.user_attrs["design"])
        name = _trial_name(t.number)
        layout = build_layout(design, name, base=base, rules=rules)
        stale_jobs.append((layout, layout_dir(out, name), config))
        names[str(layout_dir(out, name))] = t.number
    paper_job = (base, layout_dir(out, PAPER), config)
    names[str(layout_dir(out, PAPER))] = None
    queue = [paper_job, *stale_jobs]
    state = {"asked": finished + len(stale), "failed_builds": 0}

    def next_job():
        while queue:
            job = queue.pop(0)
            if finished_score(job[1], job[0], config) is None:
                return job
            reused.append(job)
        while state["asked"] < n_trials:
            trial = study.ask()
            state["asked"] += 1
            try:
                design = sample_design(trial, space, rules, base)
                name = _trial_name(trial.number)
                layout = build_layout(design, name, base=base, rules=rules)
            except EctskinError as exc:  # outside the family's feasible set: a failed trial
                log.info("trial %d not manufacturable: %s", trial.number, exc)
                study.tell(trial, state=TrialState.FAIL)
                state["failed_builds"] += 1
                continue
            trial.set_user_attr("design", design.to_dict())
            trial.set_user_attr("layout", name)
            names[str(layout_dir(out, name))] = trial.number
            job = (layout, layout_dir(out, name), config)
            if finished_score(job[1], layout, config) is not None:  # same design sampled again
                reused.append(job)
                continue
            return job
        return None

    scores: dict[str, dict] = {}
    reused: list[tuple] = []
    t0 = time.perf_counter()

    def results():
        for job, score in runner.stream(score_fn, next_job):
            yield job, score
            while reused:
                job = reused.pop()
                yield job, finished_score(job[1], job[0], config)
        while reused:
            job = reused.pop()
            yield job, finished_score(job[1], job[0], config)

    with open_runner(n_workers, scheduler) as runner:
        for job, score in results():
            number = names[str(job[1])]
            if number is None:
                scores[PAPER] = score
            else:
                loc = score["loc_mm_mean"]
                if loc is None:  # no test frame with one finger: nothing to rank it by
                    study.tell(number, state=TrialState.FAIL)
                else:
                    study.tell(number, [loc, score["n_electrodes"]])
                scores[_trial_name(number)] = score
            log.info(
                "%s: %d electrodes, %s mm", job[0].name, score["n_electrodes"], score["loc_mm_mean"]
            )
        seconds = time.perf_counter() - t0
        # every finished trial of the study (earlier runs' too) is in the report
        for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)):
            name = _trial_name(t.number)
            if name not in scores:
                design = LayoutDesign.from_dict(t.user_attrs["design"])
                layout = build_layout(design, name, base=base, rules=rules)
                done = finished_score(layout_dir(out, name), layout, config)
                scores[name] = done or score_fn(layout, layout_dir(out, name), config)
        named = [(PAPER, base)] + [(n, None) for n in sorted(k for k in scores if k != PAPER)]
        points = [
            {**scores[n], "name": n}
            for n, _ in named
            if n != PAPER and scores[n]["loc_mm_mean"] is not None
        ]
        front = pareto_front(points)
        paper = {**scores[PAPER], "name": PAPER}
        better = [
            p["name"]
            for p in points
            if paper["loc_mm_mean"] is not None
            and p["n_electrodes"] <= 8
            and p["loc_mm_mean"] < paper["loc_mm_mean"]
        ]
        extra = {
            "search": {
                "study": STUDY_FILE,
                "sampler": sampler,
                "seed": seed,
                "n_trials": n_trials,
                "n_complete": len(points),
                "n_not_manufacturable": sum(t.state == TrialState.FAIL for t in study.trials),
                "space": asdict(space),
                "rules": asdict(rules),
                "front": [p["name"] for p in front],
                "beat_paper_with_le_8_electrodes": better,
                "run_seconds": seconds,
            }
        }
        design = write_design(out, named, scores, config, runner, seconds, extra)
    fig = plot_front(points, paper)
    save_figure_atomic(fig, out / FRONT_FIGURE)
    _close(fig)
    intro = [
        f"Optuna study `{STUDY_FILE}` ({sampler}, seed {seed}): {len(points)} layouts scored; "
        f"trade-off front: {', '.join(p['name'] for p in front) or 'none'}; layouts with at most "
        f"8 electrodes that beat the paper's mean localisation error: "
        f"{', '.join(better) or 'none'}.",
        "",
    ]
    write_report(
        out, design, scores, extra_figures=[("trade-off front", FRONT_FIGURE)], intro=intro
    )
    return design


def _trial_name(number: int) -> str:
    return f"design-{number:04d}"
