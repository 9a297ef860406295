"""The reproduction's bound step: the physical limit beside the contact model's errors.

::

    bound   OUT_DIR/bound/bound.json        Cramér–Rao bound maps of every contact state's
            OUT_DIR/bound/bound.<fmt>       response field over both faces (ectskin.twin.
            OUT_DIR/bound/bound_vs_error.<fmt>  bound_field), and the bound at each test frame's
                                            true point (with ``train_trials``, at the training
                                            frames with one finger alone too); the maps, and
                                            ContactNet's error map beside the bound map per face
    force_observable
            OUT_DIR/runs/contact/force_observable.json
                                            the force error of the contact run's model, its
                                            baselines and candidates on the test frames where
                                            the bound says force is observable, where it says
                                            it is not, and where there is no bound
            OUT_DIR/runs/contact/force_sigma.<fmt>  the model's force against the true force
                                            with its σ, coloured by that split
                                            (ectskin.viz.contact.plot_force_sigma)

:func:`bound_step` takes fields already built (the field step's {state: ResponseField}); the
nuisance columns come from direct solves of each field's own sensor (``field_nuisances``):
``nuisances`` defaults to the hand's push, the inflation and the fingertip's radius
(:data:`ectskin.twin.bound.NUISANCES`); naming ``"modulus"`` among them adds the pulp's modulus
(:mod:`ectskin.twin.bound_modulus`: a table of direct solves per state, some 5 000 solves each);
``push_columns="finger"`` takes the push's columns with the finger pressing
(:mod:`ectskin.twin.bound_push`: a table of direct solves per state) instead of the untouched
state's, which make the bound beyond the wire ends several times too low.
:func:`ectskin.pipeline.metrics.bound_block` turns bound.json into metrics.json's ``bound``, and
:func:`ectskin.pipeline.metrics.force_split_keys` the force split into ``contact``'s keys.

Force is *observable* at a test frame (one finger on the skin) when the bound on the force's
standard deviation at its true point and force, in its state's field (the headline case, as
the bound section reports it), is below the bound's threshold
(:data:`ectskin.twin.bound.FORCE_THRESHOLD_N`, the inversion's ``FORCE_OBSERVABLE_N``);
frames of a state without a field have no bound and are counted apart.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError, check_option
from ectskin._files import read_json, save_figure_atomic, write_json_atomic
from ectskin.io import Recording, read_recording
from ectskin.pipeline.config import CONTACT_RUN, ReproduceConfig
from ectskin.pipeline.runner import StepRunner, digest
from ectskin.pipeline.steps import run_settings
from ectskin.twin.bound import FORCE_THRESHOLD_N, NUISANCES, cases
from ectskin.twin.bound_field import (
    MAP_SPACING_MM,
    PUSH_COLUMNS,
    StateNuisances,
    field_bound_maps,
    field_bounds,
    field_nuisances,
    reduce,
)
from ectskin.twin.field import ResponseField
from ectskin.viz import DEFAULT_DPI, figure_file
from ectskin.viz.bound import plot_bound_maps, plot_error_vs_bound
from ectskin.viz.contact import plot_force_sigma

log = logging.getLogger(__name__)

BOUND_DIR = "bound"
BOUND_FILE = "bound.json"
#: the force split of the contact run (in its folder)
FORCE_FILE = "force_observable.json"
#: the case the metrics lead with: every nuisance at its prior (the hand's push unknown, the
#: inflation to ±1 ml, the finger's radius to ±1 mm), as the contact data have them
HEADLINE_CASE = "all"


def state_key(inflation: Sequence[float]) -> str:
    """The name of a state in metrics.json, as the contact metrics' ``per_state`` write it:
    "0/20/0 ml"."""
    return "/".join(f"{float(v):g}" for v in inflation) + " ml"


def frame_points(rec: Recording, trials: Sequence[str], *, alone: bool = False
                 ) -> dict[tuple[float, ...], dict[str, Any]]:
    """{state: {face: (uv (n, 2) mm, force (n,) N)}} of the frames of ``trials`` with exactly
    one finger on the skin (the frames the contact metrics' single-finger errors are over);
    ``alone``: only those with no other finger above the skin (``by_other_finger``'s
    ``alone``)."""
    from ectskin.learn.data.contact import other_finger_height
    out: dict[tuple[float, ...], dict[str, Any]] = {}
    for name in trials:
        t = rec.trial(name)
        n_on = t.n_contacts
        if n_on is None or t.finger_uv_mm is None:
            continue
        single = n_on == 1
        if alone:
            single &= ~np.isfinite(other_finger_height(t))
        for k in range(t.n_fingers):
            f = t.finger(k)
            if f.contact is None or f.uv_mm is None or f.surface is None:
                continue
            m = single & f.contact.astype(bool)
            if not m.any():
                continue
            force = np.zeros(t.n_frames) if f.force is None else f.force
            faces = out.setdefault(tuple(float(x) for x in t.inflation), {})
            uv, fo = faces.get(f.surface, (np.zeros((0, 2)), np.zeros(0)))
            faces[f.surface] = (np.r_[uv, f.uv_mm[m]], np.r_[fo, force[m]])
    return out


def frame_bounds(
    fields: Mapping[tuple[float, ...], ResponseField],
    columns: Mapping[tuple[float, ...], StateNuisances],
    points: Mapping[tuple[float, ...], Mapping[str, Any]],
    *,
    case: str = HEADLINE_CASE,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
) -> dict[str, Any]:
    """The bound (``case``) at each test frame's true point, reduced per state (``state_key``)
    and pooled: {"per_state": {state: reduce(...) + n_frames_clipped}, "pooled": ...,
    "states_without_field": {state: n_frames}}.

    A point outside the field's extent or a force outside its range is moved to the nearest
    edge (counted in ``n_frames_clipped``); a state without a field is counted, not bounded.
    """
    check_option("case", case, cases(tuple(nuisances)))
    per_state: dict[str, Any] = {}
    missing: dict[str, int] = {}
    pooled: list[np.ndarray] = []
    for state, faces in points.items():
        field = fields.get(state)
        n_state = sum(len(f) for _, f in faces.values())
        if field is None:
            missing[state_key(state)] = n_state
            continue
        parts, clipped = [], 0
        for face, (uv, force) in faces.items():
            if face not in field.faces:
                missing[f"{state_key(state)} {face}"] = len(force)
                continue
            (ulo, uhi), (vlo, vhi) = field.spec.extent(face)
            flo, fhi = field.spec.force_range_n
            q = np.c_[np.clip(uv[:, 0], ulo, uhi), np.clip(uv[:, 1], vlo, vhi)]
            fq = np.clip(force, flo, fhi)
            clipped += int(np.sum(np.any(q != uv, axis=1) | (fq != force)))
            res = field_bounds(field, face, q, fq, columns=columns.get(state),
                               nuisances=nuisances, prior_sd=prior_sd, only=[case])[case]
            parts.append(np.stack([res["position_mm"], res["force_n"]]))
        if not parts:
            continue
        a = np.concatenate(parts, axis=1)
        pooled.append(a)
        per_state[state_key(state)] = {**reduce(a[0], a[1]), "n_frames_clipped": clipped}
    all_ = np.concatenate(pooled, axis=1) if pooled else np.zeros((2, 0))
    return {"case": case, "per_state": per_state, "pooled": reduce(all_[0], all_[1]),
            "states_without_field": missing}


def frame_force_bounds(
    fields: Mapping[tuple[float, ...], ResponseField],
    columns: Mapping[tuple[float, ...], StateNuisances],
    rec: Recording,
    trials: Sequence[str],
    *,
    case: str = HEADLINE_CASE,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """{trial: (n_frames,) N} the bound (``case``) on the force's standard deviation at each
    frame of ``trials`` with exactly one finger on the skin, at its true point and force (moved
    to the field's nearest edge as :func:`frame_bounds` does); NaN at the other frames and where
    the state or face has no field. The same bound as :func:`frame_bounds`, frame by frame."""
    check_option("case", case, cases(tuple(nuisances)))
    out: dict[str, np.ndarray] = {}
    # (state, face) -> [(trial, frame rows, uv, force)], to bound each field's points at once
    groups: dict[tuple[tuple[float, ...], str], list[tuple[str, np.ndarray, Any, Any]]] = {}
    for name in trials:
        t = rec.trial(name)
        out[name] = np.full(t.n_frames, np.nan)
        n_on = t.n_contacts
        state = tuple(float(x) for x in t.inflation)
        field = fields.get(state)
        if n_on is None or t.finger_uv_mm is None or field is None:
            continue
        for k in range(t.n_fingers):
            f = t.finger(k)
            if f.contact is None or f.uv_mm is None or f.surface not in field.faces:
                continue
            rows = np.flatnonzero((n_on == 1) & f.contact.astype(bool))
            if rows.size:
                force = np.zeros(t.n_frames) if f.force is None else f.force
                groups.setdefault((state, str(f.surface)), []).append(
                    (name, rows, f.uv_mm[rows], force[rows]))
    for (state, face), parts in groups.items():
        field = fields[state]
        (ulo, uhi), (vlo, vhi) = field.spec.extent(face)
        flo, fhi = field.spec.force_range_n
        uv = np.concatenate([p[2] for p in parts])
        q = np.c_[np.clip(uv[:, 0], ulo, uhi), np.clip(uv[:, 1], vlo, vhi)]
        fq = np.clip(np.concatenate([p[3] for p in parts]), flo, fhi)
        sd = field_bounds(field, face, q, fq, columns=columns.get(state), nuisances=nuisances,
                          prior_sd=prior_sd, only=[case])[case]["force_n"]
        a = 0
        for name, rows, _, _ in parts:
            out[name][rows] = sd[a : a + rows.size]
            a += rows.size
    return out


def contact_force_split(
    run_dir: Path,
    rec: Recording,
    bounds: Mapping[str, np.ndarray],
    *,
    threshold_n: float = FORCE_THRESHOLD_N,
    seed: int = 0,
    baselines: bool = True,
    figure: Path | None = None,
    dpi: int = DEFAULT_DPI,
) -> dict[str, Any]:
    """The force split (:func:`ectskin.learn.tasks.contact.force_split_report`) of the contact
    run in ``run_dir`` on its test trials of ``rec`` (calibrated as ``ectskin evaluate`` does),
    with ``bounds`` ({trial: (n_frames,) N}, :func:`frame_force_bounds`): {"model": the model
    the run answers with, "models": {name: split}} for that model, every other candidate of its
    candidates.json and, with ``baselines``, the contact baselines refit on its training trials
    with ``seed`` (as the run's evaluation fits them). ``threshold_n``: the bound's own
    (:data:`ectskin.twin.bound.FORCE_THRESHOLD_N`, the inversion's ``FORCE_OBSERVABLE_N``).
    With ``figure`` (a path) the run's model's force with its σ, split the same way
    (:func:`ectskin.viz.contact.plot_force_sigma`), is saved there."""
    from ectskin.learn.baselines.contact import contact_baselines
    from ectskin.learn.contact_choice import candidate_predictions
    from ectskin.learn.evaluate import calibration, read_run
    from ectskin.learn.tasks.contact import force_split_report, slot_columns
    run = read_run(run_dir)
    if run.task.name != "contact":
        raise EctskinError(f"{run_dir}: not a contact run (task {run.task.name!r})")
    calib = calibration(run, rec, None, "the contact data")
    ds = run.task.dataset(rec, reference=calib.value, **run.task.dataset_options(run.config))

    def part(names: Sequence[str]) -> Any:
        wanted = set(names)
        return ds.select(np.array([i for i, n in enumerate(ds.group_names) if n in wanted],
                                  dtype=np.int64))

    test_names = list(run.split.get("test") or [])
    missing = [n for n in test_names if n not in bounds]
    if missing:
        raise EctskinError(f"contact_force_split: no bound for test trial {missing[0]!r}")
    test, train = part(test_names), part(run.split.get("train") or [])
    sd = np.array([bounds[test.group_names[g]][f] for g, f in zip(test.group, test.frame)])
    if run.classical is not None:
        pred = run.classical.predict(test.x)
    elif run.model is not None:
        pred = run.task.predict(run.model, test)
    else:
        raise EctskinError(f"{run_dir}: the run has no model to answer with")
    if figure is not None:
        single = test.count == 1
        p0 = slot_columns(pred, 0)
        fig = plot_force_sigma(test.force[single, 0], p0["force_n"][single],
                               p0["force_sigma_n"][single], sd[single], threshold_n=threshold_n)
        save_figure_atomic(fig, figure, dpi=dpi)
    preds = {run.selected: pred}
    for name, (p, _) in candidate_predictions(run, test, pred, train).items():
        if p is not None:
            preds[name] = p
    if baselines and train.n_samples:
        for name, (p, _) in contact_baselines(train, test, train.region_centre,
                                              seed=seed).items():
            preds.setdefault(name, p)
    return {"model": run.selected, "threshold_n": threshold_n,
            "models": {k: force_split_report(test, p, sd, threshold_n) for k, p in preds.items()}}


def bound_step(
    runner: StepRunner,
    config: ReproduceConfig,
    fields: Mapping[tuple[float, ...], ResponseField],
    data: tuple[Path, Mapping[str, Any]] | None = None,
    *,
    nuisances: Sequence[str] = NUISANCES,
    prior_sd: Mapping[str, float] | None = None,
    spacing_mm: float = MAP_SPACING_MM,
    force_n: float = 1.0,
    case: str = HEADLINE_CASE,
    push_columns: str = "untouched",
    train_trials: bool = False,
) -> dict[str, Any]:
    """Steps "bound": OUT_DIR/bound/ (module docstring) from ``fields`` ({inflation: field}),
    and, with ``data`` and a trained contact run, "force_observable"; returns bound.json, with
    the force split (the step's file, not stored in bound.json) under ``force_split``.

    ``push_columns``: the push's columns from the untouched state ("untouched") or from a table
    of direct solves with the finger pressing ("finger": ``field_nuisances``, some 30 000
    solves a state on 5-mm nodes over both faces).

    ``data``: (contact.h5, its settings) of the contact step, whose test trials
    (runs/contact/split.json) are bounded frame by frame; None: the maps alone. The error map
    beside the bound (runs/contact/metrics.json's ``contact.map``) is drawn when there.
    ``train_trials``: also bound the training trials' frames with one finger on the skin and no
    other above it (bound.json's ``train_alone``), beside which the inversion's score on those
    trials stands (the inversion step's ``train_trials``: it is not trained).
    """
    if not isinstance(train_trials, bool):
        raise EctskinError(f"bound_step: train_trials must be True or False, got {train_trials!r}")
    if not fields:
        raise EctskinError("bound_step: no response fields given")
    fields = {tuple(float(x) for x in s): f for s, f in fields.items()}
    check_option("case", case, cases(tuple(nuisances)))
    check_option("push_columns", push_columns, PUSH_COLUMNS)
    out_dir = runner.out / BOUND_DIR
    run_dir = runner.out / "runs" / CONTACT_RUN
    test: list[str] = []
    train: list[str] = []
    if data is not None and (run_dir / "split.json").is_file():
        split = read_json(run_dir / "split.json", "contact run split")
        test = list(split.get("test") or [])
        train = list(split.get("train") or []) if train_trials else []
    settings: dict[str, Any] = {
        "fields": {state_key(s): f.key for s, f in fields.items()},
        "nuisances": list(nuisances), "prior_sd": dict(prior_sd or {}), "case": case,
        "spacing_mm": spacing_mm, "force_n": force_n,
        "data": digest(dict(data[1])) if data is not None else None, "test_trials": test,
        # named only when not the default, so that the steps cached before keep their key
        **({"push_columns": push_columns} if push_columns != "untouched" else {}),
        # named only when on, so that the steps cached before keep their key
        **({"train_trials": train} if train else {}),
        **config.figure_settings,
    }

    cache: dict[str, Any] = {}

    def state_columns() -> dict[tuple[float, ...], StateNuisances]:
        """The nuisance columns of every state, solved once for both steps."""
        if "columns" not in cache:
            with threadpool_limits(1):
                modulus = "modulus" in nuisances
                cache["columns"] = ({s: field_nuisances(f, modulus=modulus,
                                                        push_columns=push_columns)
                                     for s, f in fields.items()} if nuisances else {})
        return cache["columns"]

    def make() -> None:
        t0 = time.perf_counter()
        first = next(iter(fields.values()))
        with threadpool_limits(1):
            columns = state_columns()
            t_cols = time.perf_counter() - t0
            maps = field_bound_maps(fields, columns, first.spec.layout, spacing_mm=spacing_mm,
                                    force_n=force_n, nuisances=nuisances, prior_sd=prior_sd)
            t_maps = time.perf_counter() - t0 - t_cols
            if data is not None and test:
                rec = read_recording(data[0])
                for key, alone in (("test", False), ("test_alone", True)):
                    maps[key] = frame_bounds(fields, columns, frame_points(rec, test, alone=alone),
                                             case=case, nuisances=nuisances, prior_sd=prior_sd)
                if train:
                    maps["train_alone"] = frame_bounds(
                        fields, columns, frame_points(rec, train, alone=True), case=case,
                        nuisances=nuisances, prior_sd=prior_sd)
        maps["headline_case"] = case
        maps["timing"].update(columns_s=t_cols, maps_s=t_maps,
                              total_s=time.perf_counter() - t0)
        out_dir.mkdir(parents=True, exist_ok=True)
        fmt, dpi = config.figure_format, config.dpi
        save_figure_atomic(plot_bound_maps(maps, cases=[case]), out_dir / figure_file("bound", fmt),
                           dpi=dpi)
        contact = read_json(run_dir / "metrics.json", "contact run metrics") if (
            run_dir / "metrics.json").is_file() else {}
        error_map = (contact.get("contact") or {}).get("map")
        if error_map:
            save_figure_atomic(plot_error_vs_bound(error_map, maps, case=case),
                               out_dir / figure_file("bound_vs_error", fmt), dpi=dpi)
        write_json_atomic(out_dir / BOUND_FILE, maps)
        log.info("bound: %d states in %.1f s (nuisance columns %.1f s)", len(fields),
                 maps["timing"]["total_s"], t_cols)

    runner.step("bound", settings, [out_dir], make)
    result = read_json(out_dir / BOUND_FILE, "bound maps")
    trained = any((run_dir / f).is_file() for f in ("model.pt", "model.skops"))
    if data is not None and test and trained:
        force_file = run_dir / FORCE_FILE
        force_figure = run_dir / figure_file("force_sigma", config.figure_format)
        shared = ("fields", "nuisances", "prior_sd", "case", "data", "test_trials", "push_columns")
        force_settings: dict[str, Any] = {
            **{k: settings[k] for k in shared if k in settings},
            "run": digest(run_settings(config, CONTACT_RUN, dict(data[1]))),
            "baselines": config.baselines, "seed": config.seed, **config.figure_settings,
        }

        def split() -> None:
            t0 = time.perf_counter()
            rec = read_recording(data[0])
            with threadpool_limits(1):
                bounds = frame_force_bounds(fields, state_columns(), rec, test, case=case,
                                            nuisances=nuisances, prior_sd=prior_sd)
            out = contact_force_split(run_dir, rec, bounds, seed=config.seed,
                                      baselines=config.baselines, figure=force_figure,
                                      dpi=config.dpi)
            out.update(case=case, seconds=time.perf_counter() - t0)
            write_json_atomic(force_file, out)

        runner.step("force_observable", force_settings, [force_file, force_figure], split)
        result["force_split"] = read_json(force_file, "contact force split")
    return result
