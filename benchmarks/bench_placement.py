"""Benchmark: what a response field's node solves cost, piece by piece, and one state's build.

On one thread in this process (BLAS limited to one thread, as the build's workers), for one
inflation state on a :data:`~ectskin.twin.field_spec.FIELD_GRIDS` grid (``quick`` by default):

* the fingertip's placement (:meth:`SensorModel.fingertips`): per contact touch (every force
  node; its rod solved beforehand) and per hovering touch (every height node);
* a grid row of contact nodes and one of hover nodes (:mod:`ectskin.twin.field_solve`), CPU
  seconds per node;
* with ``--build``: the state's whole field built cold in this process (``workers=0``), wall
  and CPU seconds; eight such states on two workers take about 8 × CPU / 2 on an idle machine.

CPU seconds (``time.process_time``) are what an idle machine's wall time would be; on a loaded
machine compare runs made back to back. To compare two versions of ectskin, run this script
with each on ``PYTHONPATH``. Prints JSON. Run: ``.venv/bin/python benchmarks/bench_placement.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import numpy as np
from threadpoolctl import threadpool_limits

import ectskin
from ectskin.layout import default_layout
from ectskin.twin import Touch
from ectskin.twin.field_build import build_field
from ectskin.twin.field_solve import chunks_of, contact_row, hover_row
from ectskin.twin.field_spec import FIELD_GRIDS, contact_field_spec


def _cpu(fn) -> float:
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--state", default="20,20,20", help="inflation, ml per chamber")
    ap.add_argument("--grid", choices=sorted(FIELD_GRIDS), default="quick")
    ap.add_argument("--rows", type=int, default=3, help="grid rows (u) timed of each kind")
    ap.add_argument("--build", action="store_true", help="also build the whole field cold")
    ap.add_argument("--out", default=None, help="write results as JSON here")
    args = ap.parse_args()
    state = tuple(float(x) for x in args.state.split(","))
    spec = contact_field_spec(default_layout(), state, FIELD_GRIDS[args.grid])
    sensor = spec.sensor()
    face = spec.face_names[0]
    us, vs = spec.grid(face)
    rows = us[np.linspace(1, us.size - 2, args.rows).round().astype(int)]
    forces, heights = spec.forces(), spec.heights()
    out: dict = {
        "ectskin": os.path.dirname(ectskin.__file__), "state": state, "grid": args.grid,
        "load_before": os.getloadavg()[0],
    }
    with threadpool_limits(limits=1):
        sensor.capacitance(spec.inflation_ml)  # warm up
        touches = [Touch(face, (float(u), float(v))) for u in rows for v in vs]
        for t in touches:  # the rods, out of the placement's timing
            sensor.fingertips(spec.inflation_ml, t, forces)
        contact = _cpu(lambda: [sensor.fingertips(spec.inflation_ml, t, forces) for t in touches])
        hover = _cpu(lambda: [sensor.fingertips(spec.inflation_ml, t, np.zeros(heights.size),
                                                heights_mm=heights) for t in touches])
        out["placement_ms_per_touch"] = {
            "contact": round(1e3 * contact / len(touches), 2),
            "hover": round(1e3 * hover / len(touches), 2),
        }
        sensor = spec.sensor()  # rods not cached
        c = _cpu(lambda: [contact_row(sensor, spec.inflation_ml, face, float(u), vs, forces)
                          for u in rows])
        h = _cpu(lambda: [hover_row(sensor, spec.inflation_ml, face, float(u), vs, heights)
                          for u in rows])
        out["row_cpu_ms_per_node"] = {
            "contact": round(1e3 * c / (rows.size * vs.size * forces.size), 2),
            "hover": round(1e3 * h / (rows.size * vs.size * heights.size), 2),
        }
    if args.build:
        with tempfile.TemporaryDirectory() as tmp:
            w0, c0 = time.perf_counter(), time.process_time()
            build_field(spec, tmp, workers=0, progress=False)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        out["build_one_state"] = {
            "chunks": len(chunks_of(spec)), "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
            "eight_states_two_workers_s": round(8 * cpu / 2, 1),
        }
    out["load_after"] = os.getloadavg()[0]
    text = json.dumps(out)
    print(text)
    if args.out:
        with open(args.out, "w", encoding="utf-8") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
