"""The live inversion head with the person's finger pooled over the stream, against the head
without it, on a reproduction's contact test trials (twin data with people's fingers), or on
synthetic people (``--synthetic``).

::

    python benchmarks/bench_live_person.py DEMO_DIR --field-cache DIR [--every 10] [--out F]
    python benchmarks/bench_live_person.py --synthetic [--people 8] [--frames 60] [--out F]

``DEMO_DIR`` is an ``ectskin demo`` / ``reproduce`` output folder (its contact.h5, the contact
run's split and the inversion step's metrics). The inversion is built as that step built it
(the fields of the contact states from ``--field-cache``, the skin's own untouched readouts, the
hand's push columns where the step kept them, the finger tables of the coarse finger fields,
built there where missing), and each test trial is replayed through
:class:`ectskin.live.InversionHead` in frame order, every ``--every``-th frame, twice: with
``person="trial"`` (each trial one person, the pool restarted at its first frame) and with
``person="off"``. Scored on the frames with one finger on the skin: the point error, the force
MAE (all, and where the fit's force standard error is below 0.1 N), each over all fitted
frames and over those after a trial's first ``--warm-up`` fitted frames (the pool has little to
go on before), and the fit's time per frame. The two variants run side by side, one process and
one BLAS thread each.

``--synthetic``: the model is then right by construction. A field of the contact experiment's
size with closed-form node values (``bench_inversion.synthetic_field``) and a closed-form pulp
column (a softer pulp presses deeper, as a larger force does, and spreads its pad: the tests'
model), and ``--people`` people whose pulp ln(E/E0) is drawn from the twin's range (0.05-0.2
MPa about 0.1), each sliding ``--frames`` frames over the front face, read with 6 times the
electronics' noise (a frame alone then tells the pulp about as well as the population's prior
does). The same head, both ways, in one process; scored as above, plus the pulp's error.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np


def _setup(demo: Path, cache: Path):
    from ectskin._files import read_json
    from ectskin.inversion import Inversion, push_basis
    from ectskin.inversion.fit import FINGER_SCALE_SD
    from ectskin.io import read_recording
    from ectskin.io.calibration import untouched_readouts
    from ectskin.pipeline import inversion as step
    from ectskin.pipeline.config import ReproduceConfig
    from ectskin.pipeline.field import contact_fields
    from ectskin.twin.field_finger import finger_tables

    seed = read_json(demo / "metrics.json", "metrics")["seed"]
    config = ReproduceConfig(demo, seed=seed, workers=1, progress=False, field_cache=cache)
    fields = contact_fields(config)
    split = read_json(demo / "runs" / "contact" / "split.json", "split")
    done = read_json(demo / "inversion" / "metrics.json", "inversion step")
    rec = read_recording(demo / "contact.h5")
    test = [n for n in split["test"] if step._field_of(fields, rec.trial(n).inflation) is not None]
    noise = config.contact_protocol().readout
    base = untouched_readouts(rec, fields, split["test"], step.STATE_TOL_ML)
    push = ({s: push_basis(f, noise=noise) for s, f in fields.items()}
            if done["push"]["use"] else None)
    tables = finger_tables([f.spec for f in fields.values()], cache, progress=False)
    inv = Inversion(fields, noise, push=push, finger_scale_sd=FINGER_SCALE_SD, press_check=True,
                    two_fingers="coupled", untouched={s: b["pF"] for s, b in base.items()},
                    modulus=tables["modulus"], radius=tables["radius"])
    return inv, rec, test, step._dataset(rec, test)


def _replay(args):
    demo, cache, every, person, warm_up = args
    from threadpoolctl import threadpool_limits

    from ectskin.live import InversionHead

    with threadpool_limits(1):
        inv, rec, test, data = _setup(demo, cache)
        head = InversionHead(inv, rec.layout, person=person)
        rows = {(g, f): i for i, (g, f) in enumerate(zip(data.group, data.frame))}
        names = list(data.group_names)
        point, force, se_f, late, ms = [], [], [], [], []
        for name in test:
            t = rec.trial(name)
            head.new_person()
            for k, f in enumerate(range(0, t.n_frames, every)):
                frame = head(t.capacitance[f], np.full(rec.layout.n_pairs, np.nan),
                             tuple(float(x) for x in t.inflation))
                ms.append(frame.fit_ms)
                i = rows.get((names.index(name), f))
                if i is None or data.count[i] != 1 or data.force[i, 0] <= 0:
                    continue
                e = next((x for x in frame.fingers if x.contact), None)
                uv = (e.u_mm, e.v_mm) if e is not None else (np.nan, np.nan)
                point.append(float(np.hypot(*(np.asarray(uv) - data.uv[i, 0]))))
                force.append(abs((e.force_n if e is not None else 0.0) - data.force[i, 0]))
                se_f.append(e.force_se_n if e is not None else np.inf)
                late.append(k >= warm_up)
    point, force, se_f, late = map(np.asarray, (point, force, se_f, late))
    point = np.where(np.isfinite(point), point, 50.0)  # no pressing finger: charged 50 mm

    def score(sel):
        obs = sel & (se_f < 0.1)
        return {"n_frames": int(sel.sum()), "loc_mm_mean": float(point[sel].mean()),
                "loc_mm_median": float(np.median(point[sel])),
                "force_mae_n": float(force[sel].mean()),
                "force_mae_n_observable": float(force[obs].mean()) if obs.any() else None,
                "force_observable_share": float(obs.sum() / sel.sum())}

    ms = np.asarray(ms)
    return {"person": person, "all": score(np.ones(point.size, bool)), "late": score(late),
            "ms_per_frame_median": float(np.median(ms)),
            "ms_per_frame_p95": float(np.percentile(ms, 95)), "n_fits": int(ms.size)}


def _synthetic(people: int, frames: int, warm_up: int) -> dict:
    """The two heads on synthetic people (module docstring)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_inversion import realistic_spec, synthetic_field
    from threadpoolctl import threadpool_limits

    from ectskin.inversion import Inversion
    from ectskin.live import InversionHead
    from ectskin.twin.bound_modulus import ModulusTable
    from ectskin.twin.readout import ReadoutConfig, noise_pf

    field = synthetic_field(realistic_spec())
    state = tuple(field.spec.inflation_ml)
    forces = np.exp(np.linspace(*np.log(field.spec.force_range_n), 4))
    nodes, cols = {}, {}
    for face in field.faces:
        (u0, u1), (v0, v1) = field.spec.extent(face)
        u, v = np.linspace(u0, u1, 9), np.linspace(v0, v1, 21)
        U, V, F = np.meshgrid(u, v, forces, indexing="ij")
        lap = sum(field.delta(face, np.clip(U + a, u0, u1), np.clip(V + b, v0, v1), F)
                  for a, b in ((3, 0), (-3, 0), (0, 3), (0, -3))) - 4 * field.delta(face, U, V, F)
        nodes[face] = (u, v)
        cols[face] = -0.5 * F[..., None] * field.jacobian(face, U, V, F)[..., 2] - 0.6 * lap
    table = ModulusTable(nodes, forces, cols, 0.1)
    (u0, u1), (v0, v1) = field.spec.extent("front")
    noisy = ReadoutConfig(noise_scale=6.0)
    inv = Inversion({state: field}, noisy, modulus={state: table}, max_fingers=1,
                    press_check=True)
    rng = np.random.default_rng(0)
    trials = []
    for _ in range(people):
        x = float(np.log(rng.uniform(0.05, 0.2) / 0.1))
        t = np.linspace(0, 1, frames)
        cu, cv = rng.uniform(u0 + 6, u1 - 6), rng.uniform(v0 + 15, v1 - 15)
        pts = np.c_[cu + 4 * np.sin(2 * np.pi * t), cv + 10 * np.cos(2 * np.pi * t),
                    0.5 + 1.3 * np.abs(np.sin(3 * np.pi * t))]
        c = field.readout("front", pts[:, 0], pts[:, 1], pts[:, 2]) + x * table.column(
            "front", pts[:, :2], pts[:, 2])
        trials.append((x, pts, c + rng.standard_normal(c.shape) * noise_pf(c, noisy)))
    out = []
    with threadpool_limits(1):
        for person in ("trial", "off"):
            head = InversionHead(inv, field.spec.layout, person=person)
            point, force, pulp, late, ms = [], [], [], [], []
            for x, pts, cap in trials:
                head.new_person()
                for k in range(frames):
                    fr = head(cap[k], np.full(cap.shape[1], np.nan), state)
                    ms.append(fr.fit_ms)
                    e = fr.fingers[0] if fr.n_fingers and fr.fingers[0].contact else None
                    point.append(50.0 if e is None else float(np.hypot(e.u_mm - pts[k, 0],
                                                                      e.v_mm - pts[k, 1])))
                    force.append(abs((0.0 if e is None else e.force_n) - pts[k, 2]))
                    pulp.append(np.nan if e is None else abs(e.modulus_ln - x))
                    late.append(k >= warm_up)
            point, force, pulp, late = map(np.asarray, (point, force, pulp, late))
            out.append({"person": person, **{
                name: {"loc_mm_mean": float(point[sel].mean()),
                       "loc_mm_median": float(np.median(point[sel])),
                       "no_press_share": float(np.mean(point[sel] == 50.0)),
                       "force_mae_n": float(force[sel].mean()),
                       "pulp_ln_mae": float(np.nanmean(pulp[sel]))}
                for name, sel in (("all", np.ones(late.size, bool)), ("late", late))},
                "ms_per_frame_median": float(np.median(ms))})
    return {"synthetic": {"people": people, "frames": frames}, "warm_up": warm_up,
            "variants": out}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("demo", type=Path, nargs="?")
    p.add_argument("--field-cache", type=Path)
    p.add_argument("--synthetic", action="store_true",
                   help="synthetic people through a closed-form field instead of a demo folder")
    p.add_argument("--people", type=int, default=8, help="--synthetic: people (default 8)")
    p.add_argument("--frames", type=int, default=60,
                   help="--synthetic: frames per person (default 60)")
    p.add_argument("--every", type=int, default=10, help="fit every N-th frame (default 10)")
    p.add_argument("--warm-up", type=int, default=10,
                   help="fitted frames of a trial before 'late' counts (default 10)")
    p.add_argument("--out", type=Path)
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    if a.synthetic:
        result = _synthetic(a.people, a.frames, a.warm_up)
    else:
        if a.demo is None or a.field_cache is None:
            p.error("give DEMO_DIR and --field-cache, or --synthetic")
        _setup(a.demo, a.field_cache)  # the finger fields built once, before the two replays
        jobs = [(a.demo, a.field_cache, a.every, person, a.warm_up) for person in ("trial", "off")]
        with Pool(2) as pool:
            got = pool.map(_replay, jobs)
        result = {"demo": str(a.demo), "every": a.every, "warm_up": a.warm_up, "variants": got}
    result = {**result, "wall_s": time.perf_counter() - t0,
              "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                          "load_avg": os.getloadavg()}}
    text = json.dumps(result, indent=2)
    print(text)
    if a.out:
        a.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
