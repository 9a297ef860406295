"""Search the layout family (``ectskin design search``): an Optuna multi-objective study, layouts
scored as Dask tasks.

Each trial samples a :class:`~ectskin.design.family.LayoutDesign` from a :class:`SearchSpace`
(wires per face, span, shortest and longest wire, length order, lead routing, width), builds
and checks it (:func:`~ectskin.design.family.build_layout`), and scores it into
``OUT/layouts/design-NNNN/`` whose ``layout.json`` every other command takes (``ectskin simulate
--layout``). The paper's layout is scored beside them as ``paper``. Four objectives
(:data:`OBJECTIVES`):

* ``bound`` (the default): the information score
  (:func:`~ectskin.design.information.information_layout`: Cramér–Rao bound maps, no training,
  deterministic); the study minimises (worst-case position bound ``bound_mm_p95``, electrode
  count, total wire length);
* ``fit``: the same score, the study minimising the worst-case error of a fit through a field
  made with one fingertip (``fit_error_mm_p95``, docs/design.md) instead of the bound;
* ``fit-median``: the same score, the study minimising the median error of that fit
  (``fit_error_mm_median``), which ranked layouts as the trained score did on two searches but
  not on a third (BENCHMARKS.md, twentieth session);
* ``trained``: the trained score (:func:`~ectskin.design.score.score_layout`: simulate, train,
  evaluate); the study minimises (mean localisation error, electrode count).

The study lives in ``OUT/study.journal`` (Optuna's journal file storage): a rerun continues it.
Trials a killed run left running are scored again first (their finished layout folders are
reused), then new trials are asked until ``n_trials`` have finished. A rerun with another
objective, other score settings or another search space is refused (a new OUT is a new study).
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
    FAN_RISE_MM,
    MAX_PAD_MM,
    MIN_PAD_MM,
    ORDERS,
    ROUTINGS,
    FaceDesign,
    LayoutDesign,
    ManufacturingRules,
    build_layout,
)
from ectskin.design.information import (
    InformationConfig,
    finished_information,
    information_layout,
    information_to_dict,
)
from ectskin.design.report import (
    BOUND_FRONT_KEYS,
    FIT_FRONT_KEYS,
    FIT_MEDIAN_FRONT_KEYS,
    _close,
    pareto_front,
    plot_bound_front,
    plot_front,
    write_report,
)
from ectskin.design.score import ScoreConfig, finished_score, score_layout, score_to_dict
from ectskin.design.sweep import PAPER, layout_dir, write_design
from ectskin.layout import SensorLayout, default_layout

log = logging.getLogger(__name__)

STUDY_FILE = "study.journal"
STUDY_NAME = "ectskin-design"
SAMPLERS = ("tpe", "nsga2")
#: the objectives scored by the information score (no training), and what each minimises
INFORMATION_KEYS = {"bound": BOUND_FRONT_KEYS, "fit": FIT_FRONT_KEYS,
                    "fit-median": FIT_MEDIAN_FRONT_KEYS}
INFORMATION_OBJECTIVES = tuple(INFORMATION_KEYS)
OBJECTIVES = (*INFORMATION_OBJECTIVES, "trained")
FRONT_FIGURE = "figures/front.png"


@dataclass(frozen=True)
class Objective:
    """What a search minimises: ``score_fn(layout, dir, config)`` scores one layout (a Dask task),
    ``finished(dir, layout, config)`` reads a finished score back, ``keys`` are the score's fields
    the study minimises (a None value fails the trial)."""

    name: str
    config: Any
    score_fn: Callable
    finished: Callable
    keys: tuple[str, ...]
    to_entry: Callable

    def values(self, score: dict) -> list[float] | None:
        vals = [score.get(k) for k in self.keys]
        if self.name in INFORMATION_OBJECTIVES and vals[0] is None:  # unresolved: infinite
            vals[0] = float("inf")
        out = [float(v) for v in vals if v is not None]
        return out if len(out) == len(vals) else None


def objective_for(
    name: str,
    config: ScoreConfig | None = None,
    information: InformationConfig | None = None,
    score_fn: Callable | None = None,
) -> Objective:
    """The :class:`Objective` ``name`` (:data:`OBJECTIVES`) with its settings."""
    check_option("objective", name, OBJECTIVES)
    if name in INFORMATION_OBJECTIVES:
        info = information or InformationConfig()
        if name != "bound" and info.fit is None:
            raise EctskinError(
                f"design search --objective {name}: the information settings have no fit"
            )
        return Objective(
            name,
            info,
            score_fn or information_layout,
            finished_information,
            INFORMATION_KEYS[name],
            information_to_dict,
        )
    return Objective(
        name,
        config or ScoreConfig(),
        score_fn or score_layout,
        finished_score,
        ("loc_mm_mean", "n_electrodes"),
        score_to_dict,
    )


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
    flags = []
    for s in spans:
        pad = _pad(n, routing, s, width_skin, gap)
        reach = s / 2 + width / 2
        lean = s / 2 - (width_skin / 2 - gap - pad / 2)  # outer fanned lead: outwards by this
        if routing == "fan" and lean > 0:
            # its diagonal's square end at the bend reaches (w/2)(sin φ + cos φ) past the wire
            phi = np.arctan(lean / FAN_RISE_MM)
            reach = s / 2 + width / 2 * (np.sin(phi) + np.cos(phi))
        wire_ok = s / (n - 1) >= width + gap and reach <= width_skin / 2 - m
        pad_ok = pad >= MIN_PAD_MM and (routing == "fan" or s / 2 + pad / 2 <= width_skin / 2 - m)
        flags.append(bool(wire_ok and pad_ok))
    ok = np.asarray(flags)
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
        # the wire's end cap reaches half its width past its end
        room = (
            sk.v_mm[1] - sk.v_mm[0] - max(pad, MIN_PAD_MM) - rules.edge_margin_mm
            - round(width, 3) / 2
        )
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
    objective: str = "bound",
    config: ScoreConfig | None = None,
    information: InformationConfig | None = None,
    rules: ManufacturingRules | None = None,
    sampler: str = "tpe",
    seed: int = 0,
    n_workers: int = 2,
    scheduler: str | None = None,
    score_fn: Callable | None = None,
) -> dict[str, Any]:
    """Run (or continue) the study in ``out`` until ``n_trials`` trials have finished; write
    ``design.json``, the report and the front figure. Returns the design dict.

    ``objective``: ``bound`` or ``fit`` (``information`` settings) or ``trained`` (``config``);
    ``score_fn``: the per-layout scorer of the objective (a test hook; it must be importable by
    the workers)."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    space = space or SearchSpace()
    obj = objective_for(objective, config, information, score_fn)
    cfg = obj.config
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
        directions=["minimize"] * len(obj.keys),
        sampler=samplers[sampler](),
        load_if_exists=True,
    )
    settings = {
        "objective": obj.name,
        "score": cfg.to_dict(),
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
        stale_jobs.append((layout, layout_dir(out, name), cfg))
        names[str(layout_dir(out, name))] = t.number
    paper_job = (base, layout_dir(out, PAPER), cfg)
    names[str(layout_dir(out, PAPER))] = None
    queue = [paper_job, *stale_jobs]
    state = {"asked": finished + len(stale), "failed_builds": 0}

    def next_job():
        while queue:
            job = queue.pop(0)
            if obj.finished(job[1], job[0], cfg) is None:
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
            job = (layout, layout_dir(out, name), cfg)
            if obj.finished(job[1], layout, cfg) is not None:  # same design sampled again
                reused.append(job)
                continue
            return job
        return None

    scores: dict[str, dict] = {}
    reused: list[tuple] = []
    t0 = time.perf_counter()

    def results():
        for job, score in runner.stream(obj.score_fn, next_job):
            yield job, score
            while reused:
                job = reused.pop()
                yield job, obj.finished(job[1], job[0], cfg)
        while reused:
            job = reused.pop()
            yield job, obj.finished(job[1], job[0], cfg)

    with open_runner(n_workers, scheduler) as runner:
        for job, score in results():
            number = names[str(job[1])]
            if number is None:
                scores[PAPER] = score
            else:
                values = obj.values(score)
                if values is None:  # e.g. no test frame with one finger: nothing to rank it by
                    study.tell(number, state=TrialState.FAIL)
                else:
                    study.tell(number, values)
                scores[_trial_name(number)] = score
            log.info(
                "%s: %d electrodes, %s", job[0].name, score["n_electrodes"],
                ", ".join(f"{k} {score.get(k)}" for k in obj.keys[:1]),
            )
        seconds = time.perf_counter() - t0
        # every finished trial of the study (earlier runs' too) is in the report
        for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)):
            name = _trial_name(t.number)
            if name not in scores:
                design = LayoutDesign.from_dict(t.user_attrs["design"])
                layout = build_layout(design, name, base=base, rules=rules)
                done = obj.finished(layout_dir(out, name), layout, cfg)
                scores[name] = done or obj.score_fn(layout, layout_dir(out, name), cfg)
        named = [(PAPER, base)] + [(n, None) for n in sorted(k for k in scores if k != PAPER)]
        keys = obj.keys
        # each proposal with the values the study ranks it by (an unresolved bound: inf)
        points = [
            {**scores[n], "name": n, **dict(zip(keys, values))}
            for n, _ in named
            if n != PAPER and (values := obj.values(scores[n])) is not None
        ]
        front = pareto_front(points, keys)
        paper = {**scores[PAPER], "name": PAPER}
        better, claim = _better_than_paper(obj, points, paper)
        extra = {
            "objective": obj.name,
            "search": {
                "study": STUDY_FILE,
                "objective": obj.name,
                "minimised": list(keys),
                "sampler": sampler,
                "seed": seed,
                "n_trials": n_trials,
                "n_complete": len(points),
                "n_not_manufacturable": sum(t.state == TrialState.FAIL for t in study.trials),
                "space": asdict(space),
                "rules": asdict(rules),
                "front": [p["name"] for p in front],
                claim[0]: better,
                "run_seconds": seconds,
            },
        }
        result = write_design(
            out, named, scores, cfg, runner, seconds, extra, to_entry=obj.to_entry
        )
    if obj.name in INFORMATION_OBJECTIVES:
        fig = plot_bound_front(points, paper, key=obj.keys[0])
    else:
        fig = plot_front(points, paper)
    save_figure_atomic(fig, out / FRONT_FIGURE)
    _close(fig)
    intro = [
        f"Optuna study `{STUDY_FILE}` ({sampler}, seed {seed}), objective `{obj.name}` "
        f"(minimising {', '.join(keys)}): {len(points)} layouts scored; trade-off front: "
        f"{', '.join(p['name'] for p in front) or 'none'}; {claim[1]}: "
        f"{', '.join(better) or 'none'}.",
        "",
    ]
    write_report(
        out, result, scores, extra_figures=[("trade-off front", FRONT_FIGURE)], intro=intro
    )
    return result


def _better_than_paper(obj: Objective, points, paper) -> tuple[list[str], tuple[str, str]]:
    """The proposals with at most 8 electrodes that beat the paper's layout, and how: for the
    bound, a worst-case bound at most half the paper's (the issue's goal); trained, a lower mean
    localisation error (one seed: no interval, so no claim beyond this ranking)."""
    if obj.name in INFORMATION_OBJECTIVES:
        ref = paper.get("bound_mm_p95")
        names = [
            p["name"] for p in points
            if ref is not None and p["n_electrodes"] <= 8 and p["bound_mm_p95"] is not None
            and p["bound_mm_p95"] <= 0.5 * ref
        ]
        return names, (
            "half_paper_worst_bound_with_le_8_electrodes",
            "layouts with at most 8 electrodes whose worst-case position bound is at most half "
            "the paper's",
        )
    ref = paper.get("loc_mm_mean")
    names = [
        p["name"] for p in points
        if ref is not None and p["n_electrodes"] <= 8 and p["loc_mm_mean"] < ref
    ]
    return names, (
        "beat_paper_with_le_8_electrodes",
        "layouts with at most 8 electrodes with a lower mean localisation error than the paper's "
        "(one seed)",
    )


def _trial_name(number: int) -> str:
    return f"design-{number:04d}"
