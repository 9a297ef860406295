"""Benchmark: response fields of the reproduction's contact states, built, cached and checked.

The states are every combination of ``--levels`` on the three chambers (0/20 ml: 8 states).
Their fields are built cold into a fresh cache on a Dask LocalCluster of ``--workers`` processes,
then loaded again from the cache. The interpolation is checked against direct
``SensorModel.capacitance`` solves (the twin's ground truth) at random points between the nodes:
absolute error (fF) and error relative to the finger's signal |C_touch − C_untouched| per pair,
and the share of points within the acceptance bound (0.5 fF and 2 %, every pair).

Also measured, in this process on one thread: the cost of a direct contact node, of a hover
node by the Schur path and of the same hover node solved directly; and how far the Schur path
with the electrodes left where the untouched state has them (the finger moved rigidly onto the
undented skin) is from the direct contact solve: why contact nodes are full solves.

Prints JSON (and writes it with ``--out``). Run: ``.venv/bin/python benchmarks/bench_field.py``
(the grid that meets the accuracy bar, :data:`~ectskin.twin.field_spec.FINE_FIELD`, by default).

``--one-state`` measures only the CPU seconds of one state's build (the first of the states):
every chunk solved in this process on one thread, in the order a worker gets them, and the
cold build of all the states projected for ``--workers`` idle cores. The reproduction's grid,
:data:`~ectskin.twin.field_spec.QUICK_FIELD`: ``--spacing 2,4 --uniform --force-nodes 4
--height-nodes 6``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin.electrostatics import EPS0_PF_PER_MM, Panels
from ectskin.electrostatics.meshing import orthonormal_frame
from ectskin.electrostatics.schur import FixedConductors
from ectskin.layout import default_layout
from ectskin.twin import Discretisation, Touch
from ectskin.twin.field_build import build_fields
from ectskin.twin.field_solve import chunks_of, hover_row, solve_chunk
from ectskin.twin.field_spec import (
    COARSE_FIELD_MESH,
    FINE_FIELD,
    FieldSpec,
    contact_field_spec,
)

#: the coarse discretisation of the field's budget runs and tests (the twin's default is finer)
COARSE = COARSE_FIELD_MESH
ABS_PF, REL = 0.5e-3, 0.02


def _stats(x) -> dict:
    x = np.asarray(x, dtype=np.float64)
    return {"max": float(x.max()), "p95": float(np.percentile(x, 95)), "p50": float(np.median(x))}


def check_interpolation(fields, n_points: int, seed: int) -> dict:
    """Errors of the fields against direct solves at random points (half contact, half hover)."""
    rng = np.random.default_rng(seed)
    rows = {"contact": [], "hover": []}
    with threadpool_limits(limits=1):
        for field in fields:
            spec = field.spec
            sensor = spec.sensor()
            for k in range(n_points):
                face = spec.face_names[rng.integers(len(spec.face_names))]
                (ulo, uhi), (vlo, vhi) = spec.extent(face)
                u, v = float(rng.uniform(ulo, uhi)), float(rng.uniform(vlo, vhi))
                touch = Touch(face, (u, v))
                if k % 2 == 0 or not spec.height_nodes:
                    f = float(rng.uniform(*spec.force_range_n))
                    direct = sensor.capacitance(spec.inflation_ml, touch, [f])[0]
                    got, part = field.readout(face, u, v, f), "contact"
                else:
                    h = float(np.exp(rng.uniform(*np.log(spec.height_range_mm))))
                    direct = sensor.capacitance(spec.inflation_ml, touch, [0.0], heights_mm=[h])[0]
                    got, part = field.readout(face, u, v, 0.0, h), "hover"
                err = np.abs(got - direct)
                signal = np.abs(direct - field.untouched)
                rows[part].append(
                    (err.max() * 1e3, (err / signal).max(),
                     bool(np.all(err <= ABS_PF) and np.all(err <= REL * signal)))
                )
    out = {}
    for part, r in rows.items():
        if r:
            a = np.array(r, dtype=np.float64)
            out[part] = {
                "points": len(r),
                "abs_fF": _stats(a[:, 0]),
                "rel_per_pair": _stats(a[:, 1]),
                "within_bound": float(a[:, 2].mean()),
            }
    return out


def node_costs(spec: FieldSpec, n_v: int = 6) -> dict:
    """Seconds per node on one thread, wall and CPU (the CPU time is what an idle machine's
    wall time would be): direct contact, Schur hover, the same hover nodes solved directly."""
    sensor = spec.sensor()
    face = spec.face_names[0]
    (ulo, uhi), (vlo, vhi) = spec.extent(face)
    u = 0.5 * (ulo + uhi)
    v = np.linspace(vlo, vhi, n_v)
    hs, fs = spec.heights(), spec.forces()

    def timed(fn, n_nodes: int) -> dict:
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        return {"wall_s": (time.perf_counter() - w0) / n_nodes,
                "cpu_s": (time.process_time() - c0) / n_nodes}

    def contact() -> None:
        for vk in v:
            sensor.capacitance(spec.inflation_ml, Touch(face, (u, float(vk))), fs)

    def direct_hover() -> None:
        for vk in v:
            sensor.capacitance(spec.inflation_ml, Touch(face, (u, float(vk))),
                               np.zeros(hs.size), heights_mm=hs)

    with threadpool_limits(limits=1):
        sensor.capacitance(spec.inflation_ml)  # warm up
        out = {"direct_contact": timed(contact, n_v * fs.size)}
        if hs.size:
            out["schur_hover"] = timed(
                lambda: hover_row(sensor, spec.inflation_ml, face, u, v, hs), n_v * hs.size
            )
            out["direct_hover"] = timed(direct_hover, n_v * hs.size)
    return out


def _frame(n: np.ndarray) -> np.ndarray:
    e1, e2 = orthonormal_frame(n)
    return np.stack([e1, e2, n], axis=1)


def rigid_schur_error(spec: FieldSpec, points, forces) -> dict:
    """The contact readout with the electrodes where the untouched state has them and the finger
    moved rigidly from the dented skin onto the undented one (its point and axis at force F
    onto those at force 0; so only the finger's panels change: the Schur path), against the
    direct solve; per (point, force) the largest error over the pairs, absolute (fF), over the
    largest signal, and relative to each pair's own signal."""
    sensor = spec.sensor()
    p = spec.inflation_ml
    base = sensor.electrode_panels(p, None, [0.0])[0]
    cav = sensor.chamber_eps_r is not None and sensor.chamber_eps_r != sensor.eps_r
    cells = None
    if cav:
        pts, vols = sensor.cavity_cells(p, None, [0.0])
        cells = (pts[0], vols[0])
    pairs = spec.layout.pairs
    n = sensor.n_electrodes
    rows = []
    with threadpool_limits(limits=1):
        solver = FixedConductors(base, sensor.eps_r, cells=cells)
        c0 = sensor.capacitance(p)[0]
        for (face, u, v), f in itertools.product(points, forces):
            touch = Touch(face, (u, v))
            direct = sensor.capacitance(p, touch, [f])[0]
            finger = sensor.finger_panels(p, touch, [f])[0]
            tip = sensor.fingertips(p, touch, [f])[0]  # on the dented, bent body
            rest = sensor.fingertips(p, touch, [0.0])[0]  # force 0: the body as untouched
            R = _frame(rest.axis[0]) @ _frame(tip.axis[0]).T
            moved = Panels((finger.centres - tip.point_mm[0]) @ R.T + rest.point_mm[0], finger.u @ R.T,
                           finger.v @ R.T, finger.conductor, finger.n_conductors)
            K, S = solver.capacitance([moved], sensitivity_columns=n if cav else None)
            Kn = K[0, :n, :n]
            if S is not None:
                Kn = Kn + EPS0_PF_PER_MM * (sensor.chamber_eps_r - sensor.eps_r) * S[0]
            rigid = -Kn[pairs[:, 0], pairs[:, 1]]
            err = np.abs(rigid - direct)
            signal = np.abs(direct - c0)
            rows.append({"face": face, "uv_mm": [u, v], "force_n": f,
                         "abs_fF": float(err.max() * 1e3),
                         "of_signal": float(err.max() / signal.max()),
                         "rel_per_pair_max": float((err / signal).max())})
    return {"points": rows, "abs_fF_max": max(r["abs_fF"] for r in rows),
            "of_signal_max": max(r["of_signal"] for r in rows)}


def one_state_cpu(spec: FieldSpec, n_states: int, workers: int) -> dict:
    """CPU seconds of every chunk of ``spec``'s field solved here on one thread (by kind), the
    nodes per CPU second, and ``n_states`` such states on ``workers`` idle cores."""
    cpu: dict[str, float] = {}
    nodes: dict[str, int] = {}
    n_v = {f: spec.grid(f)[1].size for f in spec.face_names}
    w0 = time.perf_counter()
    with threadpool_limits(limits=1):
        for chunk in chunks_of(spec):
            c0 = time.process_time()
            solve_chunk(spec, chunk)
            cpu[chunk.kind] = cpu.get(chunk.kind, 0.0) + time.process_time() - c0
            per = {"untouched": 1, "contact": spec.force_nodes, "hover": spec.height_nodes}
            nodes[chunk.kind] = nodes.get(chunk.kind, 0) + per[chunk.kind] * (
                1 if chunk.kind == "untouched" else n_v[chunk.face])
    total = sum(cpu.values())
    return {
        "state": list(spec.inflation_ml),
        "cpu_s": {k: round(v, 2) for k, v in cpu.items()} | {"total": round(total, 2)},
        "ms_per_node": {k: round(1e3 * cpu[k] / nodes[k], 3) for k in cpu},
        "wall_s": round(time.perf_counter() - w0, 1),
        "load": [round(x, 2) for x in os.getloadavg()],
        "projected_wall_s": {"states": n_states, "workers": workers,
                             "s": round(total * n_states / workers, 1)},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0,20", help="chamber levels (ml), all combinations")
    ap.add_argument("--states", default=None,
                    help="only these states instead, e.g. '0,0,0;20,20,20' (ml per chamber)")
    ap.add_argument("--spacing", default=",".join(f"{x:g}" for x in FINE_FIELD.spacing_mm),
                    help="grid steps du,dv (mm); default FINE_FIELD's")
    ap.add_argument("--uniform", action="store_true",
                    help="no graded bands (FINE_FIELD refines beside the chambers' walls and ends)")
    ap.add_argument("--force-nodes", type=int, default=FINE_FIELD.force_nodes)
    ap.add_argument("--height-nodes", type=int, default=FINE_FIELD.height_nodes)
    ap.add_argument("--discretisation", choices=("coarse", "twin"), default="coarse")
    ap.add_argument("--window", default=None, help="u_lo,u_hi,v_lo,v_hi (mm): one area only")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--checks", type=int, default=20, help="random points checked per state")
    ap.add_argument("--rigid-checks", type=int, default=3, help="points of the rigid check")
    ap.add_argument("--out", default=None, help="write results as JSON here")
    ap.add_argument("--one-state", action="store_true",
                    help="only the CPU seconds of the first state's build, here on one thread")
    args = ap.parse_args()
    levels = [float(x) for x in args.levels.split(",")]
    states = list(itertools.product(levels, repeat=3))
    if args.states:
        states = [tuple(float(x) for x in st.split(",")) for st in args.states.split(";")]
    du, dv = (float(x) for x in args.spacing.split(","))
    window = None
    if args.window:
        a, b, c, d = (float(x) for x in args.window.split(","))
        window = ((a, b), (c, d))
    disc = COARSE if args.discretisation == "coarse" else Discretisation()
    layout = default_layout()
    grid = dataclasses.replace(
        FINE_FIELD, spacing_mm=(du, dv), force_nodes=args.force_nodes,
        height_nodes=args.height_nodes, discretisation=disc,
        fine_spacing_mm=None if args.uniform else FINE_FIELD.fine_spacing_mm,
    )
    specs = [contact_field_spec(layout, state, grid, window_mm=window) for state in states]
    if args.one_state:
        text = json.dumps(one_state_cpu(specs[0], len(specs), args.workers), indent=1)
        print(text)
        if args.out:
            Path(args.out).write_text(text + "\n")
        return
    nodes = sum(
        s.grid(f)[0].size * s.grid(f)[1].size * (s.force_nodes + s.height_nodes)
        for s in specs for f in s.face_names
    )
    result: dict = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "states": len(specs),
        "discretisation": args.discretisation,
        "spacing_mm": [du, dv],
        "fine_spacing_mm": grid.fine_spacing_mm,
        "grid": {f: [int(a.size) for a in specs[0].grid(f)] for f in specs[0].face_names},
        "force_nodes": args.force_nodes,
        "height_nodes": args.height_nodes,
        "nodes": nodes,
        "workers": args.workers,
    }
    with tempfile.TemporaryDirectory() as tmp:
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        build_fields(specs, tmp, workers=args.workers, progress=True)
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        fields = build_fields(specs, tmp, workers=args.workers, progress=False)
        cached = time.perf_counter() - t0
        result["build"] = {
            "cold_s": round(cold, 1),
            "cached_s": round(cached, 3),
            "nodes_per_s": round(nodes / cold, 1),
            "load_before": [round(x, 2) for x in load0],
            "load_after": [round(x, 2) for x in os.getloadavg()],
        }
        print(json.dumps(result["build"]), flush=True)
        costs = node_costs(specs[-1])
        contact_nodes = sum(
            s.grid(f)[0].size * s.grid(f)[1].size * s.force_nodes for s in specs for f in s.face_names
        )
        cpu = contact_nodes * costs["direct_contact"]["cpu_s"]
        if "schur_hover" in costs:
            cpu += (nodes - contact_nodes) * costs["schur_hover"]["cpu_s"]
        costs["build_cpu_estimate_s"] = round(cpu, 1)  # one core; / workers on an idle machine
        costs["build_cpu_estimate_all_levels_s"] = round(
            cpu * len(levels) ** 3 / len(specs), 1
        )  # the same for every combination of --levels (when --states picks a few)
        result["node_costs"] = costs
        print(json.dumps(costs), flush=True)
        t0 = time.perf_counter()
        q = 10_000
        fields[0].readout(fields[0].faces[0], *[np.full(q, x) for x in (
            np.mean(fields[0].spec.extent(fields[0].faces[0])[0]),
            np.mean(fields[0].spec.extent(fields[0].faces[0])[1]), 1.0)])
        result["readouts_per_s"] = round(q / (time.perf_counter() - t0))
        result["interpolation"] = check_interpolation(fields, args.checks, seed=0)
        print(json.dumps(result["interpolation"]), flush=True)
    if args.rigid_checks:
        spec = specs[-1]  # the most inflated state
        face = spec.face_names[0]
        (ulo, uhi), (vlo, vhi) = spec.extent(face)
        pts = [(face, float(u), float(v)) for u, v in zip(
            np.linspace(ulo + 0.3 * (uhi - ulo), uhi, args.rigid_checks),
            np.linspace(vlo + 0.4 * (vhi - vlo), vhi - 2.0, args.rigid_checks))]
        result["rigid_schur_contact"] = rigid_schur_error(spec, pts, (0.3, 1.0, 2.0))
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()
