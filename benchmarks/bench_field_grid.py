"""Benchmark: which response-field grid meets the acceptance bound, by the measured interpolation error.

One fine field over a window of one face (default 1 mm steps in u and v, every u of the face,
30 mm of v over a chamber's end) is built twice, with ``--nodes`` force/height nodes each
(e.g. 6 and 4). Its nodes contain those of every coarser grid whose steps are multiples of the
fine ones, so each candidate grid (``--du`` × ``--dv`` × nodes) is a sub-field of node values
that are exact; each is interpolated at the same random points (contact: a force in the range;
hover: a height in the range) and compared with direct ``SensorModel.capacitance`` solves.

Per candidate: its node count per face of the whole skin and the errors (max, p95 of the
largest error over the pairs, fF; share of points within the bound, 0.5 fF and 2 % of the
finger's signal on every pair). Prints JSON. Run:
``.venv/bin/python benchmarks/bench_field_grid.py --state 20,0,20``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin.layout import default_layout
from ectskin.twin import Touch
from ectskin.twin.field import ResponseField
from ectskin.twin.field_build import build_fields
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

ABS_PF, REL = 0.5e-3, 0.02


def _sub(values: np.ndarray, step_u: int, step_v: int) -> np.ndarray:
    return values[::step_u, ::step_v]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--state", default="20,0,20", help="ml per chamber")
    ap.add_argument("--face", default="front")
    ap.add_argument("--v-window", default="30,60", help="v_lo,v_hi (mm)")
    ap.add_argument("--fine", default="1,1", help="the fine grid's steps du,dv (mm)")
    ap.add_argument("--du", default="1,2,4,5", help="candidate u steps (multiples of the fine)")
    ap.add_argument("--dv", default="2,3,5,6,10", help="candidate v steps (multiples of the fine)")
    ap.add_argument("--nodes", default="6,4", help="force (and height) node counts")
    ap.add_argument("--points", type=int, default=150, help="random points per part")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", default="/tmp/bench_field_grid")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args()
    state = tuple(float(x) for x in args.state.split(","))
    vlo, vhi = (float(x) for x in args.v_window.split(","))
    fdu, fdv = (float(x) for x in args.fine.split(","))
    layout = default_layout()
    skin = FieldSpec(layout, state, discretisation=COARSE_FIELD_MESH, faces=(args.face,))
    (ulo, uhi), _ = skin.extent(args.face)
    window = ((ulo, uhi), (vlo, vhi))
    nodes = [int(x) for x in args.nodes.split(",")]
    fine = [
        FieldSpec(layout, state, discretisation=COARSE_FIELD_MESH, faces=(args.face,),
                  window_mm=window, spacing_mm=(fdu, fdv), force_nodes=n, height_nodes=n)
        for n in nodes
    ]
    t0 = time.perf_counter()
    fields = build_fields(fine, args.cache, workers=args.workers, progress=True)
    out: dict = {"state": state, "face": args.face, "window_mm": window,
                 "fine_build_s": round(time.perf_counter() - t0, 1)}
    spec0 = fine[0]
    sensor = spec0.sensor()
    rng = np.random.default_rng(0)
    n = args.points
    pu = rng.uniform(ulo, uhi, 2 * n)
    pv = rng.uniform(vlo, vhi, 2 * n)
    pf = rng.uniform(*spec0.force_range_n, n)
    ph = np.exp(rng.uniform(*np.log(spec0.height_range_mm), n))
    t0 = time.perf_counter()
    with threadpool_limits(limits=1):
        direct_c = np.stack([
            sensor.capacitance(state, Touch(args.face, (pu[k], pv[k])), [pf[k]])[0]
            for k in range(n)])
        direct_h = np.stack([
            sensor.capacitance(state, Touch(args.face, (pu[n + k], pv[n + k])), [0.0],
                               heights_mm=[ph[k]])[0] for k in range(n)])
    out["direct_s"] = round(time.perf_counter() - t0, 1)
    c0 = fields[0].untouched
    full_u, full_v = skin.grid(args.face)
    rows = []
    for nn, fld in zip(nodes, fields):
        fu, fv = fld.grid(args.face)
        for du in (float(x) for x in args.du.split(",")):
            for dv in (float(x) for x in args.dv.split(",")):
                su, sv = round(du / fdu), round(dv / fdv)
                if (fu.size - 1) % su or (fv.size - 1) % sv:
                    continue
                sub = dataclasses.replace(fld.spec, spacing_mm=(du, dv))
                if sub.grid(args.face)[0].size != (fu.size - 1) // su + 1:
                    continue
                cf = ResponseField(
                    sub, c0, {args.face: _sub(fld._contact[args.face], su, sv)},
                    {args.face: _sub(fld._hover[args.face], su, sv)}, key="study",
                )
                got_c = np.stack([cf.readout(args.face, pu[k], pv[k], pf[k]) for k in range(n)])
                got_h = np.stack([cf.readout(args.face, pu[n + k], pv[n + k], 0.0, ph[k])
                                  for k in range(n)])
                row = {"du": du, "dv": dv, "nodes": nn}
                n_uv = (int(np.ceil((full_u[-1] - full_u[0]) / du - 1e-9)) + 1) * (
                    int(np.ceil((full_v[-1] - full_v[0]) / dv - 1e-9)) + 1)
                row["nodes_per_face"] = n_uv * 2 * nn
                for part, got, ref in (("contact", got_c, direct_c), ("hover", got_h, direct_h)):
                    err = np.abs(got - ref)
                    sig = np.abs(ref - c0)
                    worst = err.max(axis=1) * 1e3
                    ok = np.all((err <= ABS_PF) & (err <= REL * sig), axis=1)
                    ok_abs = np.all(err <= ABS_PF, axis=1)
                    row[part] = {"max_fF": round(float(worst.max()), 3),
                                 "p95_fF": round(float(np.percentile(worst, 95)), 3),
                                 "within_bound": round(float(ok.mean()), 3),
                                 "within_0.5fF": round(float(ok_abs.mean()), 3),
                                 "rel_max": round(float((err / sig).max()), 4)}
                rows.append(row)
                print(json.dumps(row), flush=True)
    out["candidates"] = rows
    text = json.dumps(out, indent=1)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()
