"""Run an experiment protocol in the digital twin and return a :class:`~ectskin.io.Recording`.

What is computed once and what per frame (the reason the full protocol runs in about a minute):

* once per experiment and worker: the sensor's rest-state panels (:class:`SensorModel`);
* once per trial: the inflation state (bulge heights, pressures), the touch point, and the
  method-of-moments solves at ``protocol.force_nodes`` Chebyshev nodes spanning the trial's force
  range (one solve for a trial without contact). Capacitance is smooth in force, so a degree-(K−1)
  Chebyshev interpolant is exact to far below the readout noise (checked in the tests);
* per frame: the force, the interpolated capacitance, the beam bending and marker positions
  (vectorised over frames), and the readout / motion-capture noise models.

Each trial draws from its own random stream ``(seed, index)``, so the result does not depend on
the number of workers.
"""

from __future__ import annotations

import logging
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict

import numpy as np
from numpy.polynomial import chebyshev
from scipy.interpolate import PchipInterpolator
from threadpoolctl import threadpool_limits

from ectskin import __version__
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout, default_layout
from ectskin.twin.mechanics import Manipulator, ManipulatorConfig, Touch
from ectskin.twin.protocol import Protocol, TrialPlan, plan_trials
from ectskin.twin.readout import mocap, readout
from ectskin.twin.sensor import Discretisation, Finger, SensorModel

log = logging.getLogger(__name__)


def force_profile(
    n_frames: int, frame_rate_hz: float, rng: np.random.Generator, protocol: Protocol
) -> np.ndarray:
    """(n_frames,) smooth random touch force in N: monotone cubic (PCHIP) through random knots."""
    lo, hi = protocol.force_range_n
    duration = n_frames / frame_rate_hz
    n_knots = max(2, int(np.ceil(duration / protocol.force_knot_s)) + 1)
    tk = np.linspace(0.0, duration, n_knots)
    fk = rng.uniform(lo, hi, n_knots)
    t = np.arange(n_frames) / frame_rate_hz
    return np.clip(PchipInterpolator(tk, fk)(t), lo, hi)


def contact_mask(n_frames: int, frame_rate_hz: float, rng: np.random.Generator) -> np.ndarray:
    """(n_frames,) bool: finger on the skin; contact 4–10 s, lifted 1.5–4 s, alternating."""
    mask = np.zeros(n_frames, dtype=bool)
    t = float(rng.uniform(0.5, 2.0))
    on = True
    i = int(t * frame_rate_hz)
    mask[:i] = False
    while i < n_frames:
        dur = rng.uniform(4.0, 10.0) if on else rng.uniform(1.5, 4.0)
        j = min(n_frames, i + int(dur * frame_rate_hz))
        mask[i:j] = on
        on = not on
        i = j
    return mask


def chebyshev_nodes(lo: float, hi: float, k: int) -> np.ndarray:
    """(k,) Chebyshev nodes of the first kind on [lo, hi] (the interpolation nodes in force)."""
    x = np.cos(np.pi * (2 * np.arange(k) + 1) / (2 * k))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


def capacitance_over_force(
    sensor: SensorModel, inflation, touch: Touch, forces: np.ndarray, n_nodes: int
) -> np.ndarray:
    """(n, n_pairs) capacitance for every force in ``forces`` from ``n_nodes`` MoM solves.

    Chebyshev interpolation of degree n_nodes − 1 over [min, max] of the forces.
    """
    lo, hi = float(forces.min()), float(forces.max())
    if hi - lo < 1e-9:
        return np.repeat(sensor.capacitance(inflation, touch, [lo]), forces.size, axis=0)
    nodes = chebyshev_nodes(lo, hi, n_nodes)
    c_nodes = sensor.capacitance(inflation, touch, nodes)  # (K, n_pairs)
    x_nodes = (2 * nodes - (lo + hi)) / (hi - lo)
    coef = chebyshev.chebfit(x_nodes, c_nodes, n_nodes - 1)
    x = (2 * forces - (lo + hi)) / (hi - lo)
    return chebyshev.chebval(x, coef).T


def simulate_trial(
    plan: TrialPlan, protocol: Protocol, sensor: SensorModel, drift_phase: np.ndarray
) -> Trial:
    """Simulate one planned trial: mechanics → MoM → readout and motion-capture models."""
    rng = np.random.default_rng([protocol.seed, 1, plan.index])
    n = protocol.n_frames
    fps = protocol.frame_rate_hz
    t = np.arange(n) / fps
    p = plan.inflation
    labels = np.zeros(n, dtype=np.int16)
    force = np.zeros(n)
    if plan.kind == "touch":
        force = force_profile(n, fps, rng, protocol)
        contact = contact_mask(n, fps, rng) if protocol.lifts else np.ones(n, dtype=bool)
        force[~contact] = 0.0
        labels[contact] = plan.region
        c_true = np.empty((n, sensor.layout.n_pairs))
        markers_true = np.empty((n, sensor.layout.n_markers, 3))
        # one finger placement per dwell, each for an equal share of the trial
        for uv, frames in zip(plan.touch_uv_mm, np.array_split(np.arange(n), len(plan.touch_uv_mm))):
            touch = Touch(plan.surface, uv)
            on = frames[contact[frames]]
            if on.size:
                c_true[on] = capacitance_over_force(sensor, p, touch, force[on], protocol.force_nodes)
            markers_true[frames] = sensor.marker_positions(p, touch, force[frames])
        if (~contact).any():
            c_true[~contact] = sensor.capacitance(p, None, [0.0])[0]
    else:
        c_true = np.repeat(sensor.capacitance(p, None, [0.0]), n, axis=0)
        markers_true = np.repeat(sensor.marker_positions(p, None, [0.0]), n, axis=0)
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
    }
    return Trial(
        name=plan.name,
        capacitance=cap,
        timestamps=t,
        labels=labels,
        inflation=p,
        region=plan.region,
        markers=markers,
        force=force,
        meta=meta,
    )


# ---------------------------------------------------------------- parallel driver
_WORKER: dict = {}


def _init_worker(layout_json: str, manip: dict, disc: dict, eps_r: float, finger: dict,
                 protocol: dict, chamber_eps_r: float | None, limit_threads: bool = True) -> None:
    if limit_threads:  # one BLAS thread per worker process: the workers are the parallelism
        _WORKER["limits"] = threadpool_limits(1)
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


def _run_trial(args) -> Trial:
    plan, drift_phase = args
    return simulate_trial(plan, _WORKER["protocol"], _WORKER["sensor"], drift_phase)


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
) -> Recording:
    """Simulate ``protocol`` (default: the paper's) and return the recording.

    ``workers`` processes run trials in parallel (default: all cores); the result is identical
    for any worker count.
    """
    from tqdm.auto import tqdm

    protocol = protocol or Protocol()
    layout = layout or default_layout()
    manipulator = manipulator or ManipulatorConfig()
    discretisation = discretisation or Discretisation()
    finger = Finger(radius_mm=protocol.finger_radius_mm)
    plans = plan_trials(protocol, layout)
    drift_phase = np.random.default_rng([protocol.seed, 2]).uniform(0, 2 * np.pi, layout.n_pairs)
    workers = max(1, min(workers or os.cpu_count() or 1, len(plans)))
    initargs = (
        layout.to_json(),
        asdict(manipulator),
        asdict(discretisation),
        float(eps_r),
        asdict(finger),
        protocol.to_dict(),
        chamber_eps_r,
    )
    log.info("simulating %d trials x %d frames with %d worker(s)", len(plans), protocol.n_frames, workers)
    jobs = [(p, drift_phase) for p in plans]
    bar = tqdm(total=len(plans), unit="trial", desc="simulate", disable=not progress)
    trials: list[Trial] = []
    try:
        if workers == 1:  # in this process: limit BLAS threads only while simulating
            _init_worker(*initargs, limit_threads=False)
            with threadpool_limits(1):
                for job in jobs:
                    trials.append(_run_trial(job))
                    bar.update()
        else:
            with ProcessPoolExecutor(workers, initializer=_init_worker, initargs=initargs) as ex:
                for trial in ex.map(_run_trial, jobs, chunksize=1):
                    trials.append(trial)
                    bar.update()
    finally:
        bar.close()
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
    return Recording(layout=layout, trials=trials, frame_rate_hz=protocol.frame_rate_hz, meta=meta)
