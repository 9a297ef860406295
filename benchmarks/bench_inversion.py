"""Inversion benchmark: the time of one frame's fit, cold and warm, on a field of realistic size.

::

    python benchmarks/bench_inversion.py --out bench_inversion.json
    python benchmarks/bench_inversion.py --field ~/.cache/ectskin/fields/<key>   # a cached field

The field: ``--field`` (a field folder or ``field.npz``), else a synthetic field of the size of
the reproduction's contact fields (:mod:`ectskin.pipeline.field`: the paper's layout, both faces,
2 × 4 mm steps — 21 × 29 points per face —, 4 forces, 4 heights, 28 pairs, 9 744 nodes) whose
node values come from a closed-form model (:func:`synthetic_field`: each electrode a wire on
each face, a fingertip a grounded point coupled to the wires; no direct solves, so it builds in
a second). The inversion's cost depends on the field's size and smoothness, not on where its
values came from.

Frames: the field's own readouts at random points between the nodes (fingers pressing and
hovering on both faces; two-finger frames press on one face at least 15 mm apart), with the
readout's noise (:func:`ectskin.twin.readout.noise_pf`) and a small common gain drift.

* ``cold``: :meth:`Inversion.fit` of each frame alone (coarse search, then Levenberg–Marquardt),
  median and p95 per finger count (0, 1, 2); with ``--baseline-fit`` beside another version's
  (before/after a change of ``fit.py``, interleaved frame by frame so load hits both alike);
* ``warm``: streams of ``--stream`` frames of fingers sliding ``--step-mm`` per frame (a live
  stream), each frame fitted with ``warm=`` the previous frame's result
  (:class:`~ectskin.live.inversion_head.InversionHead` does this), and the same frames cold; the
  largest difference of the warm and the cold answer (mm, N) is reported beside the times.

Times are ``time.thread_time`` (the CPU this thread spent: the figure on a shared machine) and
``perf_counter`` (wall), ms, with BLAS on one thread and the process pinned to one core.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin.inversion import Inversion
from ectskin.layout import default_layout
from ectskin.live.inversion_head import load_fields
from ectskin.twin.field import ResponseField
from ectskin.twin.field_build import load_field
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec
from ectskin.twin.readout import ReadoutConfig, noise_pf


def realistic_spec(state=(0.0, 0.0, 0.0)) -> FieldSpec:
    """The spec of one of the reproduction's contact fields (``pipeline.field``'s settings)."""
    return FieldSpec(
        default_layout(), state, discretisation=COARSE_FIELD_MESH, spacing_mm=(2.0, 4.0),
        force_range_n=(0.3, 2.0), force_nodes=4, height_range_mm=(0.5, 15.0), height_nodes=4,
    )


def synthetic_field(spec: FieldSpec, seed: int = 0, alpha: float = 2e-2) -> ResponseField:
    """A field of ``spec``'s grid with closed-form node values.

    Each of the layout's electrodes is a straight wire along v on each face (at a random u,
    from a random start to a random end), a fingertip a point at height z above the face
    (z = 6 − 1.2 F^(2/3) mm pressing with F, 6 + h hovering h): its coupling to wire i is the
    potential kernel of the segment, k_i = asinh((b − v)/ρ) − asinh((a − v)/ρ) with
    ρ² = (u − x_i)² + z², and pair (i, j) loses α k_i k_j pF (the grounded finger's Schur
    complement).
    """
    rng = np.random.default_rng(seed)
    n_e = spec.layout.n_electrodes
    i, j = np.triu_indices(n_e, 1)
    if i.size != spec.n_pairs:
        raise ValueError(f"synthetic_field: {n_e} electrodes give {i.size} pairs, not {spec.n_pairs}")
    untouched = rng.uniform(0.5, 3.0, spec.n_pairs)
    contact, hover = {}, {}
    for face in spec.face_names:
        (ulo, uhi), (vlo, vhi) = spec.extent(face)
        wires = (rng.uniform(ulo, uhi, n_e), rng.uniform(vlo, vlo + 0.4 * (vhi - vlo), n_e),
                 rng.uniform(vlo + 0.6 * (vhi - vlo), vhi, n_e))
        u, v = spec.grid(face)
        for part, z in (("contact", 6.0 - 1.2 * spec.forces() ** (2 / 3)),
                        ("hover", 6.0 + spec.heights())):
            k = _couplings(u, v, z, wires)
            (contact if part == "contact" else hover)[face] = untouched - alpha * k[..., i] * k[..., j]
    return ResponseField(spec, untouched, contact, hover)


def _couplings(u: np.ndarray, v: np.ndarray, z: np.ndarray, wires) -> np.ndarray:
    """(n_u, n_v, n_z, n_wires): the segment kernel of every wire (x, a, b) at every node."""
    x, a, b = wires
    U, V, Z = (g[..., None] for g in np.meshgrid(u, v, z, indexing="ij"))
    rho = np.sqrt((U - x) ** 2 + Z**2)
    return np.arcsinh((b - V) / rho) - np.arcsinh((a - V) / rho)


def _random_finger(field, rng, face=None, contact=None, margin=2.0):
    face = face or str(rng.choice(field.faces))
    (ulo, uhi), (vlo, vhi) = field.spec.extent(face)
    u, v = rng.uniform(ulo + margin, uhi - margin), rng.uniform(vlo + margin, vhi - margin)
    contact = bool(rng.random() < 0.7) if contact is None else contact
    if contact:
        f = rng.uniform(*np.add(field.spec.force_range_n, (0.1, -0.1)))
        return face, u, v, f, 0.0
    lo, hi = np.log(field.spec.height_range_mm)
    return face, u, v, 0.0, float(np.exp(rng.uniform(lo + 0.1, min(hi, np.log(6.0)))))


def _frame(field, fingers, rng, noise):
    c = field.untouched.copy()
    for face, u, v, f, h in fingers:
        c = c + field.delta(face, u, v, f, h)
    c = c * (1.0 + rng.normal(0, 2e-4))  # a small common gain drift
    return c + rng.standard_normal(c.size) * noise_pf(c, noise)


def cold_frames(field, n: int, seed: int, noise) -> dict[int, list[np.ndarray]]:
    """``n`` frames of each finger count 0, 1, 2."""
    rng = np.random.default_rng(seed)
    out: dict[int, list[np.ndarray]] = {0: [], 1: [], 2: []}
    for _ in range(n):
        out[0].append(_frame(field, [], rng, noise))
        out[1].append(_frame(field, [_random_finger(field, rng)], rng, noise))
        while True:
            a = _random_finger(field, rng, contact=True)
            b = _random_finger(field, rng, face=a[0], contact=True)
            if math.hypot(a[1] - b[1], a[2] - b[2]) >= 15.0:
                break
        out[2].append(_frame(field, [a, b], rng, noise))
    return out


def streams(field, n_streams: int, length: int, step_mm: float, k: int, seed: int, noise):
    """``n_streams`` streams of ``length`` (frame, its fingers) of k pressing fingers sliding
    ``step_mm`` per frame in a random direction (force drifting by 0.01 N per frame)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_streams):
        face = str(rng.choice(field.faces))
        fingers = []
        for _ in range(k):
            while True:
                f = _random_finger(field, rng, face=face, contact=True, margin=8.0)
                if all(math.hypot(f[1] - g[1], f[2] - g[2]) >= 15.0 for g in fingers):
                    break
            fingers.append(f)
        (ulo, uhi), (vlo, vhi) = field.spec.extent(face)
        dirs = [rng.normal(size=2) for _ in fingers]
        dirs = [d / np.linalg.norm(d) for d in dirs]
        frames = []
        for t in range(length):
            now = []
            for (fc, u, v, f, h), d in zip(fingers, dirs):
                uu = float(np.clip(u + t * step_mm * d[0], ulo + 1, uhi - 1))
                vv = float(np.clip(v + t * step_mm * d[1], vlo + 1, vhi - 1))
                ff = float(np.clip(f + 0.01 * t, 0.4, 1.9))
                now.append((fc, uu, vv, ff, h))
            frames.append((_frame(field, now, rng, noise), now))
        out.append(frames)
    return out


def _stats(ms: list[float]) -> dict[str, float]:
    a = np.asarray(ms)
    return {"n": int(a.size), "median": round(float(np.median(a)), 4),
            "p95": round(float(np.percentile(a, 95)), 4), "max": round(float(a.max()), 4)}


def _errors(e: list[float]) -> dict[str, float]:
    """Median and p95 of the finite errors (mm), and the share that got the count and faces
    right."""
    a = np.asarray(e)
    ok = a[np.isfinite(a)]
    return {"median": round(float(np.median(ok)), 4) if ok.size else math.nan,
            "p95": round(float(np.percentile(ok, 95)), 4) if ok.size else math.nan,
            "count_and_face_right": round(float(ok.size / max(a.size, 1)), 4)}


def _timed(fn):
    c0, w0 = time.thread_time(), time.perf_counter()
    r = fn()
    return r, (time.thread_time() - c0) * 1e3, (time.perf_counter() - w0) * 1e3


def _error(r, truth) -> float:
    """The largest point error (mm) of a result against the true fingers, matched (inf when the
    count or a face is wrong)."""
    if r.n_fingers != len(truth):
        return math.inf
    best = math.inf
    for order in ([truth] if len(truth) < 2 else [truth, truth[::-1]]):
        if all(f.face == t[0] for f, t in zip(r.fingers, order)):
            best = min(best, max(math.hypot(f.u_mm - t[1], f.v_mm - t[2])
                                 for f, t in zip(r.fingers, order)))
    return best


def _diff(a, b) -> tuple[float, float, bool]:
    """The largest point (mm) and force (N) difference of two results, and whether they agree
    on the count and faces."""
    if a.n_fingers != b.n_fingers or sorted(f.face for f in a.fingers) != sorted(f.face for f in b.fingers):
        return math.inf, math.inf, False
    if not a.fingers:
        return 0.0, 0.0, True
    best = (math.inf, math.inf)
    orders = [a.fingers] if len(a.fingers) == 1 else [a.fingers, a.fingers[::-1]]
    for fa in orders:
        d = max(math.hypot(x.u_mm - y.u_mm, x.v_mm - y.v_mm) for x, y in zip(fa, b.fingers))
        f = max(abs(x.force_n - y.force_n) for x, y in zip(fa, b.fingers))
        best = min(best, (d, f))
    return best[0], best[1], True


def _load_inversion(path: Path):
    """The ``Inversion`` class of the fit module at ``path`` (a copy of
    ``ectskin/inversion/fit.py`` of another version)."""
    spec = importlib.util.spec_from_file_location("baseline_fit", path)
    if spec is None or spec.loader is None:
        raise SystemExit(f"--baseline-fit {path}: not a Python module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module.Inversion


def field_readouts(field, n_frames: int, frame_rate_hz: float, rng) -> np.ndarray:
    """bench_live's readouts with ``--fields``: (n_frames, n_pairs) pF of ``field``'s state:
    one second at rest, then a cycle of 3 s of one finger sliding on a face (pressing, its
    force varying), 1 s untouched and 2 s of two fingers sliding on the other face, with the
    readout's noise."""
    t = np.arange(n_frames) / frame_rate_hz
    phase = np.mod(np.clip(t - 1.0, 0.0, None), 6.0)
    cap = np.broadcast_to(field.untouched, (n_frames, field.n_pairs)).copy()
    faces = list(field.faces)
    for k, (lo, hi) in ((1, (0.0, 3.0)), (2, (4.0, 6.0))):
        on = (t >= 1.0) & (phase >= lo) & (phase < hi)
        face = faces[(k - 1) % len(faces)]
        (ulo, uhi), (vlo, vhi) = field.spec.extent(face)
        for j in range(k):
            # a slow ellipse per finger, well inside the face (fingers ~ half the face apart)
            cu = ulo + (uhi - ulo) * (0.35 + 0.3 * j)
            cv = vlo + (vhi - vlo) * (0.3 + 0.4 * j)
            u = cu + 0.15 * (uhi - ulo) * np.cos(2 * np.pi * 0.2 * t[on] + j)
            v = cv + 0.15 * (vhi - vlo) * np.sin(2 * np.pi * 0.2 * t[on] + j)
            f = 1.1 + 0.5 * np.sin(2 * np.pi * 0.5 * t[on])
            cap[on] += field.delta(face, u, v, f, 0.0)
    return cap + rng.standard_normal(cap.shape) * noise_pf(cap, ReadoutConfig())


def live_fields(spec: list[str], layout):
    """bench_live's ``--fields``: state → field (``synthetic``: :func:`synthetic_field` of the
    contact experiment's size at rest), and the rest-state field its recording is made of."""
    if spec == ["synthetic"]:
        field = synthetic_field(realistic_spec())
        fields = {tuple(field.spec.inflation_ml): field}
    else:
        fields = load_fields(spec)
    rest = next((f for s, f in fields.items() if not any(s)), None)
    if rest is None:
        raise SystemExit(
            "--fields: the benchmark's recording starts at rest (the touch reference), so it "
            f"needs the field of the rest state; got states {[list(s) for s in fields]}"
        )
    if tuple(rest.spec.layout.pair_names) != tuple(layout.pair_names):
        raise SystemExit("--fields: the fields are not of the paper's layout")
    return fields, rest


def run(args) -> dict:
    noise = ReadoutConfig()
    t0 = time.perf_counter()
    if args.field:
        field = load_field(args.field)
        what = f"loaded {args.field}"
    else:
        field = synthetic_field(realistic_spec())
        what = "synthetic (closed-form node values) of the contact experiment's size"
    state = field.spec.inflation_ml
    inv = Inversion({state: field}, noise)
    setup_s = time.perf_counter() - t0
    n_nodes = sum(np.prod(field.node_values(f, p).shape[:3]) for f in field.faces
                  for p in (("contact", "hover") if field.heights_mm.size else ("contact",)))
    result: dict = {
        "field": {"source": what, "faces": list(field.faces), "n_pairs": field.n_pairs,
                  "grid": {f: [g.size for g in field.grid(f)] for f in field.faces},
                  "forces": int(field.forces_n.size), "heights": int(field.heights_mm.size),
                  "n_nodes": int(n_nodes)},
        "setup_s": round(setup_s, 3),
    }
    cold = cold_frames(field, args.frames, args.seed, noise)
    base = None
    if args.baseline_fit:  # another version of the fit, timed on the same frames, interleaved
        base = _load_inversion(args.baseline_fit)({state: field}, noise)
        result["baseline_fit"] = str(args.baseline_fit)
    # a first fit of each count builds the lazy parts (the chi2 gate quantiles)
    for k in (0, 1, 2):
        inv.fit(cold[k][0], state)
        if base is not None:
            base.fit(cold[k][0], state)
    out: dict = {}
    for k, frames in cold.items():
        cpu, wall, counts, cpu_b, diff = [], [], [], [], []
        for y in frames:
            r, c, w = _timed(lambda y=y: inv.fit(y, state))
            cpu.append(c)
            wall.append(w)
            counts.append(r.n_fingers)
            if base is not None:
                rb, cb, _ = _timed(lambda y=y: base.fit(y, state))
                cpu_b.append(cb)
                dm, dn, same = _diff(r, rb)
                diff.append(max(dm, dn) if same else math.inf)
        out[str(k)] = {"cpu_ms": _stats(cpu), "wall_ms": _stats(wall),
                       "count_right": round(float(np.mean(np.asarray(counts) == k)), 3)}
        if base is not None:
            out[str(k)]["baseline_cpu_ms"] = _stats(cpu_b)
            out[str(k)]["baseline_largest_difference"] = float(np.max(diff))
    result["cold"] = out
    warm: dict = {}
    for k in (1, 2):
        ss = streams(field, args.streams, args.stream, args.step_mm, k, args.seed + k, noise)
        cpu_w, cpu_c, wall_w, d_mm, d_n, agree, e_w, e_c = [], [], [], [], [], [], [], []
        for frames in ss:
            prev = None
            for y, truth in frames:
                rw, c, w = _timed(lambda y=y, prev=prev: inv.fit(y, state, warm=prev))
                rc, cc, _ = _timed(lambda y=y: inv.fit(y, state))
                if prev is not None:  # the first frame of a stream has nothing to start from
                    cpu_w.append(c)
                    wall_w.append(w)
                    cpu_c.append(cc)
                    e_w.append(_error(rw, truth))
                    e_c.append(_error(rc, truth))
                    dm, dn, same = _diff(rw, rc)
                    agree.append(same)
                    if same:
                        d_mm.append(dm)
                        d_n.append(dn)
                prev = rw
        warm[str(k)] = {
            "warm_cpu_ms": _stats(cpu_w), "warm_wall_ms": _stats(wall_w),
            "cold_cpu_ms": _stats(cpu_c),
            "same_count_and_face": round(float(np.mean(agree)), 4),
            "warm_vs_cold_mm_max": round(float(np.max(d_mm)), 6) if d_mm else None,
            "warm_vs_cold_mm_p95": round(float(np.percentile(d_mm, 95)), 6) if d_mm else None,
            "warm_vs_cold_n_max": round(float(np.max(d_n)), 6) if d_n else None,
            "warm_error_mm": _errors(e_w),
            "cold_error_mm": _errors(e_c),
        }
    result["warm"] = warm
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--field", help="a response field folder or field.npz (default: synthetic)")
    ap.add_argument("--frames", type=int, default=150, help="cold frames per finger count")
    ap.add_argument("--streams", type=int, default=6, help="warm: streams per finger count")
    ap.add_argument("--stream", type=int, default=40, help="warm: frames per stream")
    ap.add_argument("--step-mm", type=float, default=0.3, help="warm: finger travel per frame")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--baseline-fit", type=Path, metavar="FIT.py",
        help="also time the cold fits of another version of ectskin/inversion/fit.py on the same "
        "frames, interleaved (git show REV:src/ectskin/inversion/fit.py > FIT.py), and report "
        "the largest difference of their answers (mm or N; inf: another count or face)",
    )
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU core")
    ap.add_argument("--out", type=Path, help="write the results as JSON here")
    args = ap.parse_args(argv)
    cpu = None
    if not args.no_pin:
        try:
            cpu = sorted(os.sched_getaffinity(0))[0]
            os.sched_setaffinity(0, {cpu})
        except (AttributeError, OSError):
            cpu = None
    t0 = time.perf_counter()
    with threadpool_limits(limits=1):
        result = run(args)
    result["env"] = {"python": sys.version.split()[0], "numpy": np.__version__,
                     "machine": platform.machine(), "pinned_cpu": cpu,
                     "cpus": os.cpu_count(), "load_avg": os.getloadavg()}
    result["took_s"] = round(time.perf_counter() - t0, 1)
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
