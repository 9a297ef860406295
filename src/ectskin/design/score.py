"""Score one layout in the twin: simulate a protocol, train and evaluate the models, and measure
the sensor's per-pair SNR, touch sensitivity and the conditioning of its sensitivity matrix.

:func:`score_layout` is the unit of work of a design sweep (one Dask task per layout). It writes
``<dir>/score.json`` last and atomically; :func:`finished_score` reads it back when its settings
match, so a sweep resumes without redoing finished layouts.

The default protocol (:func:`design_protocol`) is far smaller than the paper's (so that one
layout costs minutes on one core): the contact experiment's placement (touches anywhere in
their region, 2 dwells per trial, lifts) at the chambers' lowest and highest level (8 states),
2 touch trials and one no-contact trial per state of 3 s, 3 force nodes, no hover, approach or
second finger.

Every layout is scored on the same *scoring regions* (:func:`scoring_regions`: each face cut
into ``ScoreConfig.region_rows`` × ``region_cols`` rectangles, default 2 × 1: base and tip
half), not on its own: touches are drawn uniformly in them, so every layout sees the same
touches for a seed (the trial plan depends on the regions, not on the electrodes), and the few
touch trials of the small protocol still reach the test split (the split keeps one trial of
every region for training first). ``region_accuracy`` is the touch model's accuracy over these
regions and "no touch". Errors are comparable between layouts, not with the paper's numbers.
"""

from __future__ import annotations

import logging
import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError, check_option
from ectskin._files import read_json, to_jsonable, write_json_atomic, write_text_atomic
from ectskin.design.information import MESHES
from ectskin.electrostatics.reconstruct import normalise_sensitivity
from ectskin.io import write_recording
from ectskin.layout import Region, SensorLayout
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.twin import Protocol, SensorModel, simulate_experiment
from ectskin.twin.ect import ect_grid, sensitivity
from ectskin.twin.readout import ReadoutConfig, noise_pf, snr_db

log = logging.getLogger(__name__)

SCORE_FILE = "score.json"
SCORE_FORMAT = 1
TASKS = ("touch", "contact", "track")
#: relative singular value above which a direction of the sensitivity matrix counts as resolved
RANK_THRESHOLD = 1e-2


def design_protocol(seed: int = 0, **overrides: Any) -> Protocol:
    """The default design protocol (see the module docstring); ``overrides`` set any
    :class:`~ectskin.twin.Protocol` field."""
    base = Protocol(
        seed=seed,
        levels_ml=(0.0, 20.0),
        touch_trials=6,  # 2 trials ranked 5 layouts against the bound (Spearman -0.90), 6 with it (+0.90)
        duration_s=3.0,
        touch_placement="uniform",
        touch_dwells=2,
        dwell_slide_s=0.0,  # jumps from the first point to the second
        lifts=True,
        force_nodes=3,
    )
    return replace(base, **overrides)


@dataclass(frozen=True)
class ScoreConfig:
    """How a layout is scored.

    protocol : the simulated experiment (default :func:`design_protocol`).
    epochs : training epochs per task on the ``quick`` profile (assumed small defaults: the
        point is to rank layouts, not to reach the paper's accuracy).
    seed : seeds the split, the models and the protocol's own draws through ``protocol.seed``.
    tasks : which models to train; ``contact`` is required (localisation and force).
    mesh : the twin's mesh for the simulation (:data:`~ectskin.design.information.MESHES`):
        ``coarse`` (default: the information score's mesh, about 5x faster a touch trial than
        the twin's own; the paper's layout, seed 0: 42.71 against 41.87 mm) or ``default`` (the
        twin's own). A mesh other than the twin's own joins :meth:`settings`.
    """

    protocol: Protocol = field(default_factory=design_protocol)
    epochs: dict[str, int] = field(default_factory=lambda: {"touch": 15, "contact": 6, "track": 3})
    seed: int = 0
    tasks: tuple[str, ...] = TASKS
    region_rows: int = 2
    region_cols: int = 1
    mesh: str = "coarse"

    def __post_init__(self) -> None:
        check_option("mesh", self.mesh, tuple(MESHES))
        if not all(isinstance(v, int) and v >= 1 for v in (self.region_rows, self.region_cols)):
            raise EctskinError(
                f"score config: region_rows and region_cols must be integers >= 1, got "
                f"{self.region_rows!r}, {self.region_cols!r}"
            )
        unknown = sorted(set(self.tasks) - set(TASKS))
        if unknown or "contact" not in self.tasks:
            raise EctskinError(
                f"score config: tasks must include 'contact' and come from {', '.join(TASKS)}; "
                f"got {list(self.tasks)}"
            )
        for task in self.tasks:
            n = self.epochs.get(task)
            if not isinstance(n, int) or n < 1:
                raise EctskinError(
                    f"score config: epochs[{task!r}] must be an integer >= 1, got {n!r}"
                )

    def settings(self) -> dict[str, Any]:
        """Everything a finished score depends on (compared on resume)."""
        out = {
            "format": SCORE_FORMAT,
            "protocol": self.protocol.to_dict(),
            "epochs": {t: self.epochs[t] for t in self.tasks},
            "seed": self.seed,
            "tasks": list(self.tasks),
            "regions": [self.region_rows, self.region_cols],
        }
        if self.mesh != "default":
            out["mesh"] = self.mesh
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**self.settings(), "epochs": dict(self.epochs)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ScoreConfig:
        return cls(
            protocol=Protocol.from_dict(d["protocol"]),
            epochs={k: int(v) for k, v in d["epochs"].items()},
            seed=int(d["seed"]),
            tasks=tuple(d["tasks"]),
            region_rows=int(d["regions"][0]),
            region_cols=int(d["regions"][1]),
            mesh=str(d.get("mesh", "default")),
        )


def scoring_regions(layout: SensorLayout, rows: int, cols: int) -> tuple[Region, ...]:
    """Each front/back skin of ``layout`` cut into ``rows`` (along v, from the base) × ``cols``
    (along u) rectangles, numbered 1… row-major from the base, front before back."""
    regions = []
    for skin in layout.skins:
        if skin.surface not in ("front", "back"):
            continue
        u = np.linspace(*skin.u_mm, cols + 1)
        v = np.linspace(*skin.v_mm, rows + 1)
        for r in range(rows):
            for c in range(cols):
                regions.append(
                    Region(
                        len(regions) + 1,
                        skin.surface,
                        (float(u[c]), float(u[c + 1])),
                        (float(v[r]), float(v[r + 1])),
                    )
                )
    return tuple(regions)


def finished_score(dir_: str | Path, layout: SensorLayout, config: ScoreConfig) -> dict | None:
    """The score in ``dir_`` when it was made for this layout and these settings, else None."""
    path = Path(dir_) / SCORE_FILE
    if not path.is_file():
        return None
    try:
        score = read_json(path, "layout score")
    except EctskinError:
        return None
    ok = (
        isinstance(score, dict)
        and score.get("settings") == to_jsonable(config.settings())
        and score.get("layout") == to_jsonable(layout.to_dict())
    )
    return score if ok else None


def sensor_metrics(layout: SensorLayout, readout: ReadoutConfig | None = None) -> dict[str, Any]:
    """Per-pair SNR and touch sensitivity, and the conditioning of the sensitivity matrix.

    At rest (no inflation): the standing capacitance c0 of every pair and the readout's noise
    and SNR for it (:func:`~ectskin.twin.readout.snr_db`); the conductor Jacobian J (pF per mm
    of a grounded 1 mm sphere, i.e. a fingertip's first-order response) over the ECT voxel grid
    (:func:`~ectskin.twin.ect.sensitivity`). A pair's ``sensitivity_pf`` is its largest |J|, and
    ``sensitivity_snr`` that over the pair's noise. The matrix ``S = diag(1/noise) J D`` (columns
    normalised, :func:`~ectskin.electrostatics.reconstruct.normalise_sensitivity`) gives the
    singular values: ``condition_number`` σ_max/σ_min, ``rank_1pct`` how many exceed
    ``RANK_THRESHOLD`` σ_max, ``effective_rank`` exp of the entropy of σ/Σσ (Roy & Vetterli).
    """
    readout = readout or ReadoutConfig()
    sensor = SensorModel(layout)
    rest = np.zeros(sensor.manipulator.config.n_chambers)
    c0 = sensor.capacitance(rest)[0]
    noise = noise_pf(c0, readout)
    snr = snr_db(c0, readout)
    sens = sensitivity(sensor, ect_grid(layout), rest, kind="conductor")
    J = sens.jacobian
    peak = np.abs(J).max(axis=1)
    S, _, _ = normalise_sensitivity(J, row_scale=noise)
    pairs = [
        {
            "pair": layout.pair_names[k],
            "same_face": bool(layout.same_surface[k]),
            "standing_pf": float(c0[k]),
            "noise_ff": float(noise[k] * 1000.0),
            "snr_db": float(snr[k]),
            "sensitivity_pf": float(peak[k]),
            "sensitivity_snr": float(peak[k] / noise[k]),
        }
        for k in range(layout.n_pairs)
    ]
    return {
        "pairs": pairs,
        "snr_db_min": float(snr.min()),
        "snr_db_median": float(np.median(snr)),
        "sensitivity_snr_median": float(np.median(peak / noise)),
        **conditioning(S),
    }


def conditioning(S: np.ndarray) -> dict[str, Any]:
    """Singular values of ``S`` (n_meas, n_vox) and three summaries: ``condition_number``
    σ_max/σ_min (inf when σ_min is 0), ``rank_1pct`` the count above ``RANK_THRESHOLD`` σ_max,
    ``effective_rank`` exp(−Σ p log p) with p = σ/Σσ (Roy & Vetterli 2007: k equal singular
    values give k)."""
    sv = np.linalg.svd(np.asarray(S, dtype=np.float64), compute_uv=False)
    p = sv / sv.sum()
    return {
        "singular_values": sv.tolist(),
        "condition_number": float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
        "rank_1pct": int(np.sum(sv > RANK_THRESHOLD * sv[0])),
        "effective_rank": float(np.exp(-np.sum(p[p > 0] * np.log(p[p > 0])))),
    }


def score_layout(
    layout: SensorLayout, out_dir: str | Path, config: ScoreConfig | None = None
) -> dict[str, Any]:
    """Score ``layout`` into ``out_dir`` (recording, runs/<task>, ``score.json``); return the
    score. A finished score with the same settings is returned as it is; an unfinished folder
    is started over. Runs on one core (simulation in-process, torch on one thread)."""
    config = config or ScoreConfig()
    out = Path(out_dir)
    done = finished_score(out, layout, config)
    if done is not None:
        return done
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    write_text_atomic(out / "layout.json", layout.to_json() + "\n")
    t0 = time.perf_counter()
    regions = scoring_regions(layout, config.region_rows, config.region_cols)
    scored = replace(layout, regions=regions)
    rec = simulate_experiment(
        config.protocol,
        layout=scored,
        discretisation=MESHES[config.mesh],
        workers=1,
        progress=False,
    )
    data = write_recording(rec, out / "recording.h5", overwrite=True)
    t_sim = time.perf_counter() - t0
    metrics: dict[str, Any] = {}
    for task in config.tasks:
        run = out / "runs" / task
        cfg = TrainConfig(
            profile="quick",
            seed=config.seed,
            epochs=config.epochs[task],
            resume=False,
            device="cpu",
            progress=False,
            threads=1,
        )
        train_from_recording(task, data, run, cfg)
        metrics[task] = evaluate_run(
            run, data, baselines=False, figures=False, seed=config.seed, overwrite=True
        )[task]
    t_learn = time.perf_counter() - t0 - t_sim
    with threadpool_limits(1):  # one BLAS thread: the same sums wherever the task runs
        sensor = sensor_metrics(layout, config.protocol.readout)
    contact = metrics["contact"]
    score = {
        "name": layout.name,
        "n_electrodes": layout.n_electrodes,
        "n_pairs": layout.n_pairs,
        "loc_mm_mean": contact["loc_mm_mean"],
        "loc_mm_median": contact["loc_mm_median"],
        "loc_mm_p90": contact["loc_mm_p90"],
        "loc_mm_per_face": {f: v["loc_mm_mean"] for f, v in contact["per_face"].items()},
        "face_accuracy": contact["face_accuracy"],
        "region_accuracy": metrics["touch"]["accuracy"] if "touch" in metrics else None,
        "force_mae_n": contact["force_mae_n"],
        "force_rel": contact["force_rel"],
        "track_ad_mm": metrics["track"]["ad_mm_mean"] if "track" in metrics else None,
        "loc_map": _error_maps(contact["map"]),
        "sensor": sensor,
        "seconds": {"simulate": t_sim, "learn": t_learn, "total": time.perf_counter() - t0},
        "settings": config.settings(),
        "layout": layout.to_dict(),
    }
    write_json_atomic(out / SCORE_FILE, score)
    return to_jsonable(score)  # as the file holds it


def _error_maps(contact_map: dict[str, Any]) -> dict[str, Any]:
    """The contact metrics' per-face maps as plain arrays (mean error per cell, mm; NaN where
    no test frame fell)."""
    out = {}
    for face, m in contact_map.items():
        if not isinstance(m, dict) or "mean_mm" not in m:
            continue
        out[face] = {
            k: np.asarray(m[k], dtype=np.float64).tolist()
            for k in ("u_edges", "v_edges", "mean_mm")
        }
    return out


def score_to_dict(score: dict[str, Any]) -> dict[str, Any]:
    """The headline fields of a score (the ``design.json`` entry without maps, pairs and the
    layout)."""
    keep = {k: v for k, v in score.items() if k not in ("loc_map", "layout", "sensor", "settings")}
    s = score["sensor"]
    keep["sensor"] = {k: v for k, v in s.items() if k not in ("pairs", "singular_values")}
    return keep


__all__ = [
    "SCORE_FILE",
    "ScoreConfig",
    "conditioning",
    "design_protocol",
    "finished_score",
    "score_layout",
    "score_to_dict",
    "scoring_regions",
    "sensor_metrics",
]
