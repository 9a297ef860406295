"""Run an experiment protocol in the digital twin and return a :class:`~ectskin.io.Recording`.

What is computed once, per trial and per frame:

* once per experiment and worker: the sensor's rest-state panels (:class:`SensorModel`);
* once per trial: the experimenter's plan (the finger's path and force, the hand's push; see
  :mod:`ectskin.twin.human`), the inflation state, and the method-of-moments solves of
  :class:`TouchResponse` (about a dozen for a touch trial, one without contact);
* per frame: the readout from :class:`TouchResponse`'s smooth model of the frame's state, the
  rod's equilibrium for the markers (vectorised over frames), and the readout and
  motion-capture noise models.

Each trial draws from its own random stream ``(seed, index)``, so the result does not depend on
the number of workers; a second finger (``Protocol.second_finger``) from its own,
``(seed, index, 2)``, and :class:`SecondFingerResponse` adds its effect to :class:`TouchResponse`.

Size: the per-trial readout models (one finger, a second finger) and the parallel driver that
runs them belong together: the driver's workers build exactly these models.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, fields, replace
from typing import Any

import numpy as np
from numpy.polynomial import chebyshev
from threadpoolctl import threadpool_limits

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout, default_layout
from ectskin.twin.human import finger_path, hand_push, second_finger_path
from ectskin.twin.mechanics import Handling, Manipulator, ManipulatorConfig, Touch
from ectskin.twin.protocol import Protocol, TrialPlan, plan_trials, region_bounds
from ectskin.twin.readout import mocap, readout
from ectskin.twin.sensor import Discretisation, Finger, SensorModel

log = logging.getLogger(__name__)


def chebyshev_nodes(lo: float, hi: float, k: int) -> np.ndarray:
    """(k,) Chebyshev nodes of the first kind on [lo, hi] (the interpolation nodes in force)."""
    x = np.cos(np.pi * (2 * np.arange(k) + 1) / (2 * k))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


def _cheb_fit(x_lo: float, x_hi: float, nodes: np.ndarray, values: np.ndarray, x: np.ndarray):
    """Evaluate at ``x`` the Chebyshev interpolant of ``values`` (K, P) given at ``nodes``."""
    if x_hi - x_lo < 1e-12:
        return np.repeat(values[:1], np.size(x), axis=0)
    xn = (2 * nodes - (x_lo + x_hi)) / (x_hi - x_lo)
    coef = chebyshev.chebfit(xn, values, nodes.size - 1)
    return chebyshev.chebval((2 * np.asarray(x) - (x_lo + x_hi)) / (x_hi - x_lo), coef).T


class TouchResponse:
    """The readout of one touch trial as a smooth function of the frame's state.

    The finger's state moves along a few smooth coordinates within a trial, so the trial needs a
    handful of method-of-moments solves, not one per frame:

    * the force F (contact) or the height h (above the skin): a Chebyshev interpolant at the
      trial's mean point, over the trial's force range (``force_nodes`` solves) and over log h
      (``force_nodes`` + 2 solves, only if the finger leaves the skin). The finger's off-axis
      push is a fixed fraction of F, so it rides along;
    * the point (u, v) on the skin: a quadratic in (u − ū, v − v̄) from a 5-point stencil and
      one diagonal point, ``slide_step_mm`` apart, at the middle force (5 solves; the middle
      Chebyshev node is the stencil's centre), added to the frames in contact;
    * the hand's push m (fixed direction, varying magnitude): a slope at the middle force
      (1 solve), added to every frame.

    The model's error against direct solves is bounded in the tests.
    """

    slide_step_mm = 1.0

    def __init__(self, sensor, inflation, surface, path, handling, push_dir, protocol):
        self.sensor, self.p, self.surface = sensor, inflation, surface
        self.n_solves = 0  # method-of-moments solves this trial took
        self.shear_per_n = np.zeros(2)
        on = path.contact
        if on.any():
            self.shear_per_n = (path.shear_n[on] / path.force_n[on, None]).mean(axis=0)
        self.push_dir = push_dir
        self.push_point = handling.push
        self.uv0 = path.uv_mm[on].mean(axis=0) if on.any() else path.uv_mm.mean(axis=0)
        mags = self._push_magnitude(handling)
        self.m0 = float(mags.mean()) if mags is not None else 0.0
        dm = float(np.ptp(mags)) / 2 if mags is not None else 0.0
        k = protocol.force_nodes | 1  # odd: the middle node is the range's centre
        self.f_lo = self.f_hi = 0.0
        if on.any():
            self.f_lo, self.f_hi = float(path.force_n[on].min()), float(path.force_n[on].max())
        self.f_nodes = chebyshev_nodes(self.f_lo, self.f_hi, k)
        self.c_nodes = self._solve(self.f_nodes) if on.any() else None
        f_mid = np.array([0.5 * (self.f_lo + self.f_hi)])
        if on.any():
            centre = self.c_nodes[k // 2]
        else:  # the finger never lands: the stencil is taken at the lowest height
            centre = None
        off = ~on
        if off.any():
            h = np.log(path.height_mm[off])
            self.h_lo, self.h_hi = float(h.min()), float(h.max())
            self.h_nodes = chebyshev_nodes(self.h_lo, self.h_hi, k + 2)
            self.c_hover = self._solve(np.zeros(k + 2), heights=np.exp(self.h_nodes))
        heights = None if on.any() else np.exp([self.h_lo])
        forces = f_mid if on.any() else np.zeros(1)
        if centre is None:
            centre = self._solve(forces, heights=heights)[0]
        # the reference state the other terms are taken at (the second finger's too)
        self.ref_forces, self.ref_heights, self.centre = forces, heights, centre
        d = self.slide_step_mm
        stencil = np.stack(
            [self._solve(forces, du=du, heights=heights)[0] for du in ((d, 0), (-d, 0), (0, d), (0, -d), (d, d))]
        )
        self.g_u = (stencil[0] - stencil[1]) / (2 * d)
        self.g_v = (stencil[2] - stencil[3]) / (2 * d)
        self.g_uu = (stencil[0] - 2 * centre + stencil[1]) / d**2
        self.g_vv = (stencil[2] - 2 * centre + stencil[3]) / d**2
        # C(d, d) = C + d(g_u + g_v) + d²(g_uu + g_vv)/2 + d² g_uv
        self.g_uv = (
            stencil[4] - centre - d * (self.g_u + self.g_v) - 0.5 * d**2 * (self.g_uu + self.g_vv)
        ) / d**2
        self.h_slope = None
        if dm > 0:
            self.h_slope = (self._solve(forces, dm=dm, heights=heights)[0] - centre) / dm

    def _push_magnitude(self, handling):
        if handling.push_force_n is None or self.push_dir is None:
            return None
        return np.asarray(handling.push_force_n) @ self.push_dir

    def _handling(self, forces, m, second=None):
        forces = np.atleast_1d(forces)
        shear = forces[:, None] * self.shear_per_n[None, :]
        if second is not None:  # (F, 2 fingers, 2)
            shear = np.stack([shear, second[1][:, None] * second[2][None, :]], axis=1)
        push = None
        if self.push_point is not None:
            push = np.repeat((m * self.push_dir)[None, :], forces.size, axis=0)
        return Handling(shear_n=shear, push=self.push_point, push_force_n=push)

    def _solve(self, forces, *, du=(0.0, 0.0), dm=0.0, heights=None, second=None):
        """MoM solves at ``forces`` (K,) of this finger at its mean point + ``du``; ``second``:
        (Touch, forces (K,), shear per N (2,)) of a second finger pressing as well."""
        forces = np.atleast_1d(np.asarray(forces, dtype=np.float64))
        self.n_solves += forces.size
        touch = Touch(self.surface, (float(self.uv0[0] + du[0]), float(self.uv0[1] + du[1])))
        handling = self._handling(forces, self.m0 + dm, second)
        if second is None:
            return self.sensor.capacitance(self.p, touch, forces, handling, heights_mm=heights)
        both = np.column_stack([forces, second[1]])
        h = None if heights is None else np.column_stack([heights, np.zeros(forces.size)])
        return self.sensor.capacitance(self.p, (touch, second[0]), both, handling, heights_mm=h)

    def __call__(self, path, handling) -> np.ndarray:
        """(n, n_pairs) readout of every frame of ``path``."""
        n = path.force_n.size
        out = np.empty((n, self.sensor.layout.n_pairs))
        on = path.contact
        if on.any():
            out[on] = _cheb_fit(self.f_lo, self.f_hi, self.f_nodes, self.c_nodes, path.force_n[on])
        off = ~on
        if off.any():
            out[off] = _cheb_fit(
                self.h_lo, self.h_hi, self.h_nodes, self.c_hover, np.log(path.height_mm[off])
            )
        # the point's quadratic applies in contact (above the skin the finger's point matters far
        # less, and hover frames are taken at the trial's mean point), or everywhere if the
        # finger never lands (then the stencil was taken at the lowest height)
        where = on if on.any() else np.ones(n, dtype=bool)
        du = path.uv_mm[where] - self.uv0
        u, v = du[:, :1], du[:, 1:]
        out[where] += (
            self.g_u * u + self.g_v * v + 0.5 * self.g_uu * u**2 + 0.5 * self.g_vv * v**2
            + self.g_uv * u * v
        )
        mags = self._push_magnitude(handling)
        if self.h_slope is not None and mags is not None:
            out += self.h_slope * (mags - self.m0)[:, None]
        return out


class SecondFingerResponse:
    """What a second finger adds to a :class:`TouchResponse`, in the frames where it presses.

    Taken around the first model's reference state (its middle force, or its lowest height if
    the first finger never lands) and the second finger's mean point ū₂ and middle force F̄₂:

    * Δ(F₁): the change the second finger at (ū₂, F̄₂) makes, as a Chebyshev interpolant over the
      first finger's force nodes (``force_nodes`` solves with both fingers, the single-finger
      values at the same nodes already known): the two fingers' coupling through the body and
      the field, as the first finger's force varies. Frames where the first finger is off the
      skin take Δ at the reference state;
    * B(F₂) − B(F̄₂): the second finger's own force, a Chebyshev interpolant over
      ``second_nodes`` forces at the reference state (the middle node is shared, so
      ``second_nodes`` − 1 solves);
    * a slope in the second finger's point (u₂, v₂) − ū₂: forward differences, ``slide_step_mm``
      apart (2 solves; the pad rolls and slides a millimetre or so).

    The first finger's point and the hand's push enter through the first model, unchanged by the
    second finger. The model's error against direct solves is bounded in the tests.
    """

    second_nodes = 3
    slide_step_mm = 1.0

    def __init__(self, first: TouchResponse, path1, surface2: str, path2):
        self.first = first
        on2 = path2.contact
        if not on2.any():
            raise EctskinError("second finger: its path never touches the skin")
        n0 = first.n_solves
        self.shear2 = (path2.shear_n[on2] / path2.force_n[on2, None]).mean(axis=0)
        self.uv2 = path2.uv_mm[on2].mean(axis=0)
        self.surface2 = surface2
        self.f2_lo, self.f2_hi = float(path2.force_n[on2].min()), float(path2.force_n[on2].max())
        k2 = self.second_nodes | 1
        self.f2_nodes = chebyshev_nodes(self.f2_lo, self.f2_hi, k2)
        f2_mid = self.f2_nodes[k2 // 2]
        ref_f, ref_h = first.ref_forces, first.ref_heights
        self.on1 = path1.contact.any()
        if self.on1:  # the coupling over the first finger's force nodes
            both = self._solve(first.f_nodes, np.full(first.f_nodes.size, f2_mid))
            self.delta_nodes = both - first.c_nodes
            ref_two = both[first.f_nodes.size // 2]
        else:
            ref_two = self._solve(ref_f, [f2_mid], heights=ref_h)[0]
        self.delta_ref = ref_two - first.centre
        others = np.delete(self.f2_nodes, k2 // 2)
        c2 = self._solve(np.repeat(ref_f, others.size), others, heights=_rep(ref_h, others.size))
        self.c2_nodes = np.insert(c2, k2 // 2, ref_two, axis=0)
        d = self.slide_step_mm
        steps = self._solve(
            np.repeat(ref_f, 2), [f2_mid] * 2, heights=_rep(ref_h, 2), du2=((d, 0.0), (0.0, d))
        )
        self.g2 = (steps - ref_two) / d  # (2, P): d C / d u2, d C / d v2
        self.ref_two = ref_two
        self.n_solves = first.n_solves - n0

    def _solve(self, forces1, forces2, *, heights=None, du2=None):
        forces2 = np.asarray(forces2, dtype=np.float64)
        if du2 is None:
            t2 = Touch(self.surface2, (float(self.uv2[0]), float(self.uv2[1])))
            return self.first._solve(forces1, heights=heights, second=(t2, forces2, self.shear2))
        rows = []
        for k, (du, dv) in enumerate(du2):  # one solve per displaced point
            t2 = Touch(self.surface2, (float(self.uv2[0] + du), float(self.uv2[1] + dv)))
            one = None if heights is None else heights[k : k + 1]
            second = (t2, forces2[k : k + 1], self.shear2)
            rows.append(
                self.first._solve(np.atleast_1d(forces1)[k : k + 1], heights=one, second=second)[0]
            )
        return np.stack(rows)

    def __call__(self, path1, path2) -> np.ndarray:
        """(n, n_pairs) change of the readout the second finger makes (0 where it is away)."""
        out = np.zeros((path2.force_n.size, self.ref_two.size))
        on2 = path2.contact
        on = on2 & path1.contact if self.on1 else np.zeros_like(on2)
        f = self.first
        if on.any():
            out[on] = _cheb_fit(f.f_lo, f.f_hi, f.f_nodes, self.delta_nodes, path1.force_n[on])
        off = on2 & ~on
        out[off] = self.delta_ref
        b = _cheb_fit(self.f2_lo, self.f2_hi, self.f2_nodes, self.c2_nodes, path2.force_n[on2])
        du = path2.uv_mm[on2] - self.uv2
        out[on2] += b - self.ref_two + du @ self.g2
        return out


def _rep(heights, n: int):
    """``heights`` (1,) repeated n times (None stays None)."""
    return None if heights is None else np.repeat(heights, n)


def simulate_trial(
    plan: TrialPlan, protocol: Protocol, sensor: SensorModel, drift_phase: np.ndarray
) -> Trial:
    """Simulate one planned trial: the experimenter → mechanics → MoM → readout and mocap models."""
    rng = np.random.default_rng([protocol.seed, 1, plan.index])
    n = protocol.n_frames
    fps = protocol.frame_rate_hz
    t = np.arange(n) / fps
    p = plan.inflation
    n_markers = sensor.layout.n_markers
    truth = {  # per-frame ground truth; without a finger: no contact, no point, no height
        "contact": np.zeros(n, dtype=bool),
        "finger_uv_mm": np.full((n, 2), np.nan),
        "force_n": np.zeros(n),
        "finger_height_mm": np.full(n, np.nan),
    }
    labels = np.zeros(n, dtype=np.int16)
    n_solves = 1
    if plan.kind == "touch":
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
        # one readout model per dwell: the finger moves to a new point for each equal share of
        # the trial (finger_path), and each model is accurate around its own point
        for rows in np.array_split(np.arange(n), len(plan.touch_uv_mm)):
            seg = _rows(path, rows)
            seg_hand = _rows(hand, rows)
            seg2 = _rows(path2, rows) if path2 is not None else None
            c_true[rows], markers_true[rows], solves = _touch_segment(
                sensor, p, plan, protocol, seg, seg_hand, seg2, push_dir
            )
            n_solves += solves
        if path2 is not None:  # (a trial of a few frames may end before it lands)
            truth.update(
                contact2=path2.contact,
                finger2_uv_mm=path2.uv_mm,
                force2=path2.force_n,
                finger2_surface=plan.second_surface,
            )
        labels[path.contact] = plan.region
        truth.update(
            contact=path.contact,
            finger_uv_mm=path.uv_mm,
            force_n=path.force_n,
            finger_height_mm=path.height_mm,
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
    if plan.second_surface is not None:
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
        finger_surface=plan.surface,
        contact2=truth.get("contact2"),
        finger2_uv_mm=truth.get("finger2_uv_mm"),
        force2=truth.get("force2"),
        finger2_surface=truth.get("finger2_surface"),
        meta=meta,
    )


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
    handling = Handling(path.shear_n, hand.push, hand.push_force_n)
    response = TouchResponse(sensor, p, plan.surface, path, hand, push_dir, protocol)
    c_true = response(path, hand)
    on = path.contact
    one_dwell = len(plan.touch_uv_mm) == 1  # (then every frame, as before dwells had models)
    touch = Touch(
        plan.surface, tuple((path.uv_mm if one_dwell or not on.any() else path.uv_mm[on]).mean(0))
    )
    solves = response.n_solves
    if path2 is not None and path2.contact.any():  # a second finger presses for a while
        second = SecondFingerResponse(response, path, plan.second_surface, path2)
        c_true = c_true + second(path, path2)
        solves = response.n_solves
        uv2 = tuple(path2.uv_mm[path2.contact].mean(axis=0))
        touch = (touch, Touch(plan.second_surface, uv2))
        forces = np.column_stack([path.force_n, path2.force_n])
        handling = Handling(
            np.stack([path.shear_n, path2.shear_n], axis=1), hand.push, hand.push_force_n
        )
        return c_true, sensor.marker_positions(p, touch, forces, handling), solves
    return c_true, sensor.marker_positions(p, touch, path.force_n, handling), solves


def _second_path(plan: TrialPlan, protocol: Protocol, sensor: SensorModel, n: int, fps: float):
    """The second finger's path, from its own random stream (the trial's other draws stay)."""
    rng = np.random.default_rng([protocol.seed, 1, plan.index, 2])
    lo, hi = region_bounds(sensor.layout.region(plan.second_region), protocol.touch_margin)
    return second_finger_path(n, fps, np.asarray(plan.second_uv_mm), lo, hi, protocol, rng)


# ---------------------------------------------------------------- parallel driver
# Workers die with the driver. A worker blocks on the task queue, whose pipe every worker holds
# open too, so it never sees the driver go: without the guards below a killed `simulate` left its
# workers running for good. Linux kills a worker when its parent dies (prctl PR_SET_PDEATHSIG);
# elsewhere a watchdog thread exits the worker once it is orphaned (its parent process changes),
# and a worker whose driver died before it started exits at once. A driver that stops on an
# exception (Ctrl-C) cancels the queued trials and terminates its workers (_stop_workers).
_WORKER: dict = {}
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_WATCHDOG_PERIOD_S = 0.5


def _die_with_parent(driver_pid: int) -> None:
    """End this worker process when its parent (the driver, or the driver's fork server) goes."""
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watchdog still works
            log.debug("prctl(PR_SET_PDEATHSIG) unavailable; relying on the watchdog")
    try:
        os.kill(driver_pid, 0)
    except ProcessLookupError:  # the driver died before this worker started
        os._exit(1)
    except OSError:
        pass

    def watch() -> None:
        while os.getppid() == parent:  # an orphan is adopted by another process
            time.sleep(_WATCHDOG_PERIOD_S)
        os._exit(1)

    threading.Thread(target=watch, name="ectskin-worker-watchdog", daemon=True).start()


def _stop_workers(ex: ProcessPoolExecutor) -> None:
    """Cancel the queued trials and terminate the running workers now (not after their trials)."""
    ex.shutdown(wait=False, cancel_futures=True)
    procs = list((getattr(ex, "_processes", None) or {}).values())
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=5)


def _init_worker(driver_pid: int | None, layout_json: str, manip: dict, disc: dict,
                 eps_r: float, finger: dict, protocol: dict, chamber_eps_r: float | None,
                 limit_threads: bool = True) -> None:
    if driver_pid is not None:  # a worker process: it dies with the driver
        _die_with_parent(driver_pid)
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
) -> Recording:
    """Simulate ``protocol`` (default: the paper's) and return the recording.

    ``workers`` processes run trials in parallel (default: all cores); the result is identical
    for any worker count. ``trials``: only the planned trials of these names, in plan order,
    each the same as in the whole experiment (its random numbers come from the seed and its
    index in the plan); a name not in the plan is an error.
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
            _init_worker(None, *initargs, limit_threads=False)
            with threadpool_limits(1):
                for job in jobs:
                    trials.append(_run_trial(job))
                    bar.update()
        else:
            ex = ProcessPoolExecutor(
                workers, initializer=_init_worker, initargs=(os.getpid(), *initargs)
            )
            try:
                for trial in ex.map(_run_trial, jobs, chunksize=1):
                    trials.append(trial)
                    bar.update()
            except BaseException:
                _stop_workers(ex)
                raise
            ex.shutdown()
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
    if trials is not None:
        meta["only_trials"] = [p.name for p in plans]
    return Recording(layout=layout, trials=trials, frame_rate_hz=protocol.frame_rate_hz, meta=meta)
