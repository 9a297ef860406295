"""Run an experiment protocol in the digital twin and return a :class:`~ectskin.io.Recording`.

What is computed once, per trial and per frame:

* once per experiment and worker: the sensor's rest-state panels (:class:`SensorModel`);
* once per trial: the experimenter's plan (the finger's path and force, the hand's push; see
  :mod:`ectskin.twin.human`), the inflation state, and the method-of-moments solves of
  :class:`~ectskin.twin.response.TouchResponse` (about a dozen for a touch trial, one without
  contact);
* per frame: the readout from the response model of the frame's state, the rod's equilibrium for
  the markers (vectorised over frames), and the readout and motion-capture noise models.

Each trial draws from its own random stream ``(seed, 1, index)``, so the result does not depend
on the number of workers (:mod:`ectskin.twin.pool` runs the trials); a second finger
(``Protocol.second_finger``) from its own, ``(seed, 1, index, 2)``, and
:class:`~ectskin.twin.response.SecondFingerResponse` adds its effect. The fingers' sizes and pulps
(``Protocol.finger_variability``, :func:`~ectskin.twin.human.trial_fingers`) come from another,
``(seed, 1, index, 3)``, so that switching them off leaves every other draw of the trial as it
was; a touch trial solves with its own fingers (a shallow copy of the worker's sensor,
:meth:`~ectskin.twin.sensor.SensorModel.with_fingers`) and records each finger's radius and
modulus on the fingers axis (``Trial.finger_radius_mm``, ``Trial.finger_modulus_mpa``).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, fields, replace
from typing import Any

import numpy as np

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout, default_layout
from ectskin.twin.field import ResponseField
from ectskin.twin.field_response import FieldTouchResponse, TrialFields
from ectskin.twin.finger import Finger
from ectskin.twin.human import (
    dwell_points,
    finger_path,
    hand_push,
    second_finger_path,
    trial_fingers,
)
from ectskin.twin.mechanics import Handling, Manipulator, ManipulatorConfig, Touch
from ectskin.twin.pool import run_in_workers
from ectskin.twin.protocol import Protocol, TrialPlan, plan_trials, region_bounds
from ectskin.twin.readout import mocap, readout
from ectskin.twin.response import SecondFingerResponse, TouchResponse
from ectskin.twin.sensor import Discretisation, SensorModel

log = logging.getLogger(__name__)


def simulate_trial(
    plan: TrialPlan,
    protocol: Protocol,
    sensor: SensorModel,
    drift_phase: np.ndarray,
    fields: TrialFields | None = None,
) -> Trial:
    """Simulate one planned trial: the experimenter → mechanics → MoM → readout and mocap models.

    ``fields``: the states' response fields, read by a touch trial of a protocol with
    ``response="field"`` (:class:`~ectskin.twin.field_response.FieldTouchResponse`)."""
    rng = protocol.rng(1, plan.index)
    n = protocol.n_frames
    fps = protocol.frame_rate_hz
    t = np.arange(n) / fps
    p = plan.inflation
    n_markers = sensor.layout.n_markers
    truth = {  # per-frame ground truth of one finger; away: no contact, no point, no height
        "contact": np.zeros(n, dtype=bool),
        "finger_uv_mm": np.full((n, 2), np.nan),
        "force_n": np.zeros(n),
        "finger_height_mm": np.full(n, np.nan),
    }
    surfaces: tuple[str | None, ...] = (plan.surface,)
    labels = np.zeros(n, dtype=np.int16)
    n_solves = 1
    sizes: dict[str, np.ndarray | None] = {"finger_radius_mm": None, "finger_modulus_mpa": None}
    if plan.kind == "touch":
        assert plan.touch_uv_mm is not None  # (plan_trials gives every touch trial its points)
        fingers = trial_fingers(
            protocol, sensor.finger, protocol.rng(1, plan.index, 3)
        )
        trial_sensor = sensor.with_fingers(*fingers)
        reg = sensor.layout.region(plan.region)
        lo, hi = region_bounds(reg, protocol.touch_margin)
        path = finger_path(n, fps, np.asarray(plan.touch_uv_mm), lo, hi, protocol, rng)
        hand = hand_push(n, fps, protocol, rng, sensor.manipulator.config)
        push_dir = None
        if hand.push_force_n is not None:
            norms = np.linalg.norm(hand.push_force_n, axis=1)
            push_dir = hand.push_force_n[int(np.argmax(norms))] / max(norms.max(), 1e-12)
        path2 = None
        if plan.second_surface is not None:
            path2 = _second_path(plan, protocol, sensor, n, fps)
        c_true = np.empty((n, sensor.layout.n_pairs))
        markers_true = np.empty((n, n_markers, 3))
        n_solves = 0
        dwells = readout_segments(n, fps, np.asarray(plan.touch_uv_mm), protocol)
        if protocol.response == "field":
            if fields is None:
                raise EctskinError("simulate: protocol.response is 'field' but no fields given")
            response = FieldTouchResponse(
                fields.get(p), trial_sensor, p, str(plan.surface), path,
                hand, push_dir, (lo, hi), plan.second_surface, path2,
            )
            c_true = response(path, hand, path2)
            n_solves = response.n_solves
        # one readout model per dwell: the finger moves to a new point for each equal share of
        # the trial (finger_path), and each model is accurate around its own point (a finger
        # sliding from point to point has one per stretch of its way: readout_segments)
        for rows in dwells:
            seg = _rows(path, rows)
            seg_hand = _rows(hand, rows)
            seg2 = _rows(path2, rows) if path2 is not None else None
            if protocol.response == "field":
                markers_true[rows] = _touch_markers(trial_sensor, p, plan, seg, seg_hand, seg2)
                continue
            c_true[rows], markers_true[rows], solves = _touch_segment(
                trial_sensor, p, plan, protocol, seg, seg_hand, seg2, push_dir
            )
            n_solves += solves
        # the fingers axis: finger 0, and the second finger as finger 1 (a trial of a few
        # frames may end before it lands)
        paths = (path,) if path2 is None else (path, path2)
        surfaces = (plan.surface,) if path2 is None else (plan.surface, plan.second_surface)
        labels[path.contact] = plan.region
        sizes = {
            "finger_radius_mm": np.array([f.radius_mm for f in fingers[: len(paths)]]),
            "finger_modulus_mpa": np.array([f.pulp_modulus_mpa for f in fingers[: len(paths)]]),
        }
        truth.update(
            contact=np.stack([q.contact for q in paths], axis=1),
            finger_uv_mm=np.stack([q.uv_mm for q in paths], axis=1),
            force_n=np.stack([q.force_n for q in paths], axis=1),
            finger_height_mm=np.stack([q.height_mm for q in paths], axis=1),
        )
    else:
        c_true = np.repeat(sensor.capacitance(p, None, [0.0]), n, axis=0)
        markers_true = np.repeat(sensor.marker_positions(p, None, [0.0]), n, axis=0)
        markers_true = markers_true.reshape(n, n_markers, 3)
    cap = readout(c_true, plan.start_s + t, rng, protocol.readout, drift_phase)
    markers = mocap(markers_true, rng, protocol.mocap, plan.marker_delay_frames, plan.occluded)
    meta = {
        "kind": plan.kind,
        "state": plan.state,
        "surface": plan.surface or "",
        "touch_uv_mm": [list(uv) for uv in plan.touch_uv_mm] if plan.touch_uv_mm else [],
        "marker_delay_frames": plan.marker_delay_frames,
        "occluded": plan.occluded,
        "start_s": plan.start_s,
        "mom_solves": n_solves,
    }
    if plan.kind == "touch" and protocol.response == "field" and fields is not None:
        meta["response_field"] = fields.get(p).key
    if plan.second_surface is not None and plan.second_uv_mm is not None:
        meta["second_finger"] = {
            "surface": plan.second_surface,
            "region": plan.second_region,
            "touch_uv_mm": list(plan.second_uv_mm),
        }
    return Trial(
        name=plan.name,
        capacitance=cap,
        timestamps=t,
        labels=labels,
        inflation=p,
        region=plan.region,
        markers=markers,
        force=truth["force_n"],
        contact=truth["contact"],
        finger_uv_mm=truth["finger_uv_mm"],
        finger_height_mm=truth["finger_height_mm"],
        finger_surface=surfaces,
        **sizes,
        meta=meta,
    )


#: the longest stretch (mm) of a sliding finger's way that one readout model of a solved trial
#: covers: TouchResponse's quadratic in the point stays within about 0.2 fF of direct solves up
#: to 2 mm from its centre (0.3-0.4 fF at 3.3 mm, 5-6 fF at 6 mm, measured)
SLIDE_SEGMENT_MM = 4.0


def readout_segments(
    n: int, fps: float, aimed_uv: np.ndarray, protocol: Protocol
) -> list[np.ndarray]:
    """The frames of each readout model of a touch trial: one per dwell (the equal shares of
    :func:`~ectskin.twin.human.dwell_points`). A solved trial (``response="solve"``) whose
    finger slides from dwell to dwell (``dwell_slide_s`` > 0) cuts each dwell further, at equal
    lengths along its way (the aimed path, no random draw), into stretches of at most
    :data:`SLIDE_SEGMENT_MM`: one quadratic model around a single point would be off by several
    fF at the ends of a slide of 5 mm or more."""
    dwells = np.array_split(np.arange(n), len(aimed_uv))
    if protocol.slide_s <= 0 or protocol.response != "solve":
        return dwells
    way = dwell_points(n, fps, np.asarray(aimed_uv, dtype=np.float64), protocol.slide_s)
    out: list[np.ndarray] = []
    for rows in dwells:
        along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(way[rows], axis=0), axis=1))]
        k = int(np.ceil(along[-1] / SLIDE_SEGMENT_MM))
        if k <= 1:
            out.append(rows)
            continue
        cuts = np.searchsorted(along, along[-1] * np.arange(1, k) / k)
        out.extend(part for part in np.split(rows, cuts) if part.size)
    return out


def _rows(obj: Any, rows: np.ndarray) -> Any:
    """``obj`` (a FingerPath or a Handling) with its per-frame arrays cut to ``rows``."""
    changes = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and f.name != "push":
            changes[f.name] = v[rows]
    return replace(obj, **changes)


def _touch_segment(sensor, p, plan, protocol, path, hand, path2, push_dir):
    """Readout (n, P), true markers (n, M, 3) and MoM solves of the frames of one dwell."""
    response = TouchResponse(sensor, p, plan.surface, path, hand, push_dir, protocol)
    c_true = response(path, hand)
    solves = response.n_solves
    if path2 is not None and path2.contact.any():  # a second finger presses for a while
        second = SecondFingerResponse(response, path, plan.second_surface, path2)
        c_true = c_true + second(path, path2)
        solves = response.n_solves
    return c_true, _touch_markers(sensor, p, plan, path, hand, path2), solves


def _touch_markers(sensor, p, plan, path, hand, path2) -> np.ndarray:
    """True markers (n, M, 3) of the frames of one dwell: the finger(s) at the dwell's mean point."""
    handling = Handling(path.shear_n, hand.push, hand.push_force_n)
    on = path.contact
    one_dwell = len(plan.touch_uv_mm) == 1  # (then every frame, as before dwells had models)
    touch = Touch(
        plan.surface, tuple((path.uv_mm if one_dwell or not on.any() else path.uv_mm[on]).mean(0))
    )
    if path2 is not None and path2.contact.any():  # a second finger presses for a while
        uv2 = tuple(path2.uv_mm[path2.contact].mean(axis=0))
        both = (touch, Touch(plan.second_surface, uv2))
        forces = np.column_stack([path.force_n, path2.force_n])
        handling = Handling(
            np.stack([path.shear_n, path2.shear_n], axis=1), hand.push, hand.push_force_n
        )
        return sensor.marker_positions(p, both, forces, handling)
    return sensor.marker_positions(p, touch, path.force_n, handling)


def _second_path(plan: TrialPlan, protocol: Protocol, sensor: SensorModel, n: int, fps: float):
    """The second finger's path, from its own random stream (the trial's other draws stay)."""
    rng = protocol.rng(1, plan.index, 2)
    lo, hi = region_bounds(sensor.layout.region(plan.second_region), protocol.touch_margin)
    return second_finger_path(n, fps, np.asarray(plan.second_uv_mm), lo, hi, protocol, rng)


# ---------------------------------------------------------------- per worker
_WORKER: dict = {}


def _init_worker(layout_json: str, manip: dict, disc: dict, eps_r: float, finger: dict,
                 protocol: dict, chamber_eps_r: float | None, fields: dict | None = None) -> None:
    """Build the worker's sensor model and protocol once (:func:`ectskin.twin.pool.run_in_workers`)."""
    layout = SensorLayout.from_json(layout_json)
    _WORKER["sensor"] = SensorModel(
        layout,
        Manipulator(ManipulatorConfig(**manip)),
        Discretisation(**disc),
        eps_r,
        Finger(**finger),
        chamber_eps_r=chamber_eps_r,
    )
    _WORKER["protocol"] = Protocol.from_dict(protocol)
    _WORKER["fields"] = None if fields is None else TrialFields(fields)  # read on first use


def _run_trial(args) -> Trial:
    plan, drift_phase = args
    return simulate_trial(
        plan, _WORKER["protocol"], _WORKER["sensor"], drift_phase, _WORKER["fields"]
    )


def _only(plans: list[TrialPlan], names: Sequence[str]) -> list[TrialPlan]:
    """The plans named in ``names`` (plan order)."""
    wanted = set(names)
    unknown = sorted(wanted - {p.name for p in plans})
    if unknown:
        raise EctskinError(
            f"simulate: trial(s) {unknown[:5]} are not in the protocol's plan ({len(plans)} "
            f"trials, e.g. {[p.name for p in plans[:3]]})"
        )
    return [p for p in plans if p.name in wanted]


def simulate_experiment(
    protocol: Protocol | None = None,
    *,
    layout: SensorLayout | None = None,
    manipulator: ManipulatorConfig | None = None,
    discretisation: Discretisation | None = None,
    eps_r: float = 2.0,
    chamber_eps_r: float | None = 1.0,
    workers: int | None = None,
    progress: bool = True,
    trials: Sequence[str] | None = None,
    fields: Mapping[tuple[float, ...], ResponseField | str | os.PathLike] | None = None,
) -> Recording:
    """Simulate ``protocol`` (default: the paper's) and return the recording.

    ``workers`` processes run trials in parallel (default: all cores); the result is identical
    for any worker count. ``trials``: only the planned trials of these names, in plan order,
    each the same as in the whole experiment (its random numbers come from the seed and its
    index in the plan); a name not in the plan is an error. ``fields``: for a protocol with
    ``response="field"``, the response field of every inflation state with touch trials (state
    → :class:`~ectskin.twin.field.ResponseField`, or better the path of its saved file or cache
    folder, which each worker reads once); they must be of this layout, body and permittivities.
    """
    from tqdm.auto import tqdm

    protocol = protocol or Protocol()
    layout = layout or default_layout()
    manipulator = manipulator or ManipulatorConfig()
    discretisation = discretisation or Discretisation()
    finger = Finger(radius_mm=protocol.finger_radius_mm)
    plans = plan_trials(protocol, layout)
    if trials is not None:
        plans = _only(plans, trials)
    trial_fields = _check_fields(
        protocol, plans, fields, layout, manipulator, float(eps_r), chamber_eps_r
    )
    drift_phase = protocol.rng(2).uniform(0, 2 * np.pi, layout.n_pairs)
    workers = max(1, min(workers or os.cpu_count() or 1, len(plans)))
    initargs = (
        layout.to_json(),
        asdict(manipulator),
        asdict(discretisation),
        float(eps_r),
        asdict(finger),
        protocol.to_dict(),
        chamber_eps_r,
        None if trial_fields is None else trial_fields.sources(),
    )
    log.info("simulating %d trials x %d frames with %d worker(s)", len(plans), protocol.n_frames, workers)
    jobs = [(p, drift_phase) for p in plans]
    simulated: list[Trial] = []
    with tqdm(total=len(plans), unit="trial", desc="simulate", disable=not progress) as bar:
        for trial in run_in_workers(
            _run_trial, jobs, workers=workers, init=_init_worker, initargs=initargs
        ):
            simulated.append(trial)
            bar.update()
    meta = {
        "source": "ectskin.twin",
        "ectskin_version": __version__,
        "protocol": protocol.to_dict(),
        "manipulator": asdict(manipulator),
        "discretisation": asdict(discretisation),
        "finger": asdict(finger),
        "eps_r": float(eps_r),
        "chamber_eps_r": chamber_eps_r,
    }
    if trials is not None:
        meta["only_trials"] = [p.name for p in plans]
    return Recording(layout=layout, trials=simulated, frame_rate_hz=protocol.frame_rate_hz, meta=meta)


def _check_fields(protocol, plans, fields, layout, manipulator, eps_r, chamber_eps_r):
    """The fields of a ``response="field"`` protocol as :class:`TrialFields`, checked at the
    door: one per state with touch trials, of this layout, body and permittivities, covering the
    touched faces; None for ``response="solve"`` (which refuses fields)."""
    if protocol.response != "field":
        if fields is not None:
            raise EctskinError(
                "simulate: fields were given, but protocol.response is 'solve' (set "
                "response='field' to read them)"
            )
        return None
    if fields is None:
        raise EctskinError(
            "simulate: protocol.response is 'field'; give the states' response fields (fields=, "
            "e.g. from ectskin.pipeline.field.contact_fields)"
        )
    out = TrialFields(fields)
    faces: dict[tuple[float, ...], set] = {}
    for plan in plans:
        if plan.kind == "touch":
            used = faces.setdefault(tuple(plan.inflation), set())
            used.update(f for f in (plan.surface, plan.second_surface) if f is not None)
    for state, used in faces.items():
        spec = out.get(state).spec
        same = {
            "layout": spec.layout.to_json() == layout.to_json(),
            "manipulator": spec.manipulator == manipulator,
            "eps_r": spec.eps_r == eps_r,
            "chamber_eps_r": spec.chamber_eps_r == chamber_eps_r,
        }
        differ = [k for k, ok in same.items() if not ok]
        if differ:
            raise EctskinError(
                f"simulate: the response field of state {list(state)} ml differs from the "
                f"simulation in {differ}; build the fields for this layout and body"
            )
        missing = sorted(used - set(spec.face_names))
        if missing:
            raise EctskinError(
                f"simulate: the response field of state {list(state)} ml covers the faces "
                f"{list(spec.face_names)}, the trials touch {missing} as well"
            )
    return out
