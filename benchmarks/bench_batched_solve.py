"""Benchmark: a response field's contact solves one at a time (NumPy/SciPy) and batched on torch
devices (CPU, a CUDA GPU where PyTorch sees one).

Three measurements, on the reproduction's fullest contact state (20/20/20 ml):

* ``mom``: the method-of-moments part only. The panel sets of one contact row (every v of a grid
  column × the field's 4 forces; the twin places the fingers once, outside the timing) are solved
  by ``SensorModel``'s own one-at-a-time readout and by
  :func:`ectskin.electrostatics.batched.readout_batch` on each device; solves per second (best
  of ``--repeat``) and the largest difference from the NumPy readouts, relative to the largest
  readout. Done for the field's coarse mesh and for the twin's default mesh (the paper
  experiment's solves).
* ``rows`` / ``hover_rows``: whole contact / hover chunks
  (:func:`ectskin.twin.field_solve.solve_chunk`, placement included) per device, seconds per
  chunk.
* ``build`` (with ``--build``): the cold build of the reproduction's contact fields into a fresh
  cache on a Dask LocalCluster of ``--workers`` processes, per device (one CUDA context per
  worker on a GPU), wall seconds.

Run: ``.venv/bin/python benchmarks/bench_batched_solve.py [--devices numpy,cpu,cuda] [--build]``.
Prints JSON (and writes it with ``--out``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import tempfile
import time

import numpy as np
import torch

from ectskin.electrostatics.batched import readout_batch
from ectskin.pipeline.config import ReproduceConfig
from ectskin.pipeline.field import contact_field_specs
from ectskin.twin import Discretisation, Touch
from ectskin.twin.field_build import build_fields
from ectskin.twin.field_solve import chunks_of, solve_chunk


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def mom(spec, devices: list[str], repeat: int, n_v: int | None) -> dict:
    """Solves per second of one contact row's panel sets on each device."""
    sensor = spec.sensor()
    face = spec.face_names[0]
    u_grid, v_grid = spec.grid(face)
    v_grid = v_grid if n_v is None else v_grid[:n_v]
    u = float(u_grid[u_grid.size // 2])
    sets = [
        row for v in v_grid
        for row in sensor.solve_sets(spec.inflation_ml, Touch(face, (u, float(v))), spec.forces())
    ]
    kw = dict(
        eps_r=sensor.eps_r, n_electrodes=sensor.n_electrodes, pairs=sensor.layout.pairs,
        chamber_eps_r=sensor.chamber_eps_r, blocks=[b for _, b, _ in sets],
        cells=[c for _, _, c in sets] if sensor.chamber_eps_r not in (None, sensor.eps_r) else None,
    )
    out: dict = {"sets": len(sets), "panels": sets[0][0].n_panels,
                 "cavity_cells": None if kw["cells"] is None else int(len(sets[0][2][0]))}
    ref = None
    for device in devices:
        best = np.inf
        for _ in range(repeat + 1):  # the first run warms up (CUDA context, kernels)
            t = time.perf_counter()
            if device == "numpy":
                got = np.stack([sensor._readout(p, c, b) for p, b, c in sets])
            else:
                got, ok = readout_batch([p for p, _, _ in sets], device=device, **kw)
                _sync(device)
                if not ok.all():
                    raise RuntimeError(f"{device}: {np.sum(~ok)} sets did not factor")
            best = min(best, time.perf_counter() - t)
        if ref is None:
            ref = got
        out[device] = {
            "seconds": best, "solves_per_s": len(sets) / best,
            "max_rel_diff_vs_first": float(np.max(np.abs(got - ref)) / np.max(np.abs(ref))),
        }
    return out


def rows(spec, devices: list[str], n_rows: int, kind: str = "contact") -> dict:
    """Seconds per whole chunk of ``kind`` (placement + solves) on each device."""
    chunks = [c for c in chunks_of(spec) if c.kind == kind]
    pick = [chunks[k] for k in np.linspace(0, len(chunks) - 1, n_rows).astype(int)]
    out: dict = {"chunks": [c.name for c in pick]}
    ref = None
    for device in devices:
        dev = None if device == "numpy" else device
        solve_chunk(spec, pick[0], device=dev)  # warm up
        t = time.perf_counter()
        vals = [solve_chunk(spec, c, device=dev) for c in pick]
        sec = (time.perf_counter() - t) / len(pick)
        if ref is None:
            ref = vals
        diff = max(float(np.max(np.abs(a - b))) for a, b in zip(vals, ref))
        out[device] = {"s_per_chunk": sec, "nodes_per_s": vals[0].shape[0] * vals[0].shape[1] / sec,
                       "max_abs_diff_pf_vs_first": diff}
    return out


def build(config, devices: list[str], workers: int) -> dict:
    """Wall seconds of the cold build of the contact fields, per device."""
    out: dict = {"workers": workers, "states": len(contact_field_specs(config))}
    for device in devices:
        with tempfile.TemporaryDirectory() as cache:
            t = time.perf_counter()
            build_fields(contact_field_specs(config), cache, workers=workers, progress=False,
                         device=device)  # "numpy": the one-at-a-time path
            out[device] = {"wall_s": time.perf_counter() - t}
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    default = "numpy,cpu" + (",cuda" if torch.cuda.is_available() else "")
    p.add_argument("--devices", default=default)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--rows", type=int, default=4, help="contact chunks timed per device")
    p.add_argument("--fine-v", type=int, default=8,
                   help="grid points v of the default-mesh row (its solves are slow on a CPU)")
    p.add_argument("--build", action="store_true")
    p.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)))
    p.add_argument("--out")
    a = p.parse_args()
    devices = [d.strip() for d in a.devices.split(",") if d.strip()]
    config = ReproduceConfig(out_dir="unused", progress=False)  # (specs only: nothing is written)
    spec = max(contact_field_specs(config), key=lambda s: sum(s.inflation_ml))
    fine = dataclasses.replace(spec, discretisation=Discretisation())
    result = {
        "machine": {"platform": platform.platform(), "cpus": len(os.sched_getaffinity(0)),
                    "torch": torch.__version__,
                    "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None},
        "state_ml": list(spec.inflation_ml),
        "mom_field_mesh": mom(spec, devices, a.repeat, None),
        "mom_default_mesh": mom(fine, devices, a.repeat, a.fine_v),
        "rows": rows(spec, devices, a.rows),
        "hover_rows": rows(spec, devices, a.rows, "hover"),
    }
    if a.build:
        result["build"] = build(config, [d for d in devices if d != "cpu"], a.workers)
    text = json.dumps(result, indent=1, default=str)
    print(text)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
