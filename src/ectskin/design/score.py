"""Score one layout in the twin: simulate a protocol, train and evaluate the models, and measure
the sensor's per-pair SNR, touch sensitivity and the conditioning of its sensitivity matrix.

:func:`score_layout` is the unit of work of a design sweep (one Dask task per layout). It writes
``<dir>/score.json`` last and atomically; :func:`finished_score` reads it back when its settings
match, so a sweep resumes without redoing finished layouts.

The design protocol (:func:`design_protocol`) is far smaller than the paper's: the contact
experiment's placement (touches anywhere in their region, lifts) at the chambers' lowest and
highest level (8 states), one no-contact trial per state, no hover, approach or second finger.
How its touch trials are read (``ScoreConfig.response``): by default (``field``) from the
response fields of the protocol's states, built once per layout and cached, on a protocol with
many more touch points (12 touch trials of 15 s per state, a new point every 0.5 s:
:mod:`ectskin.design.score_field`); or (``solve``) by method-of-moments solves per dwell, 6
touch trials of 3 s per state with 2 dwells and 3 force nodes (a few minutes a layout and seed
on one core, but too few distinct touches to train on: its seed-to-seed spread hides the
differences between layouts).

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
from ectskin.design.score_field import (
    DEFAULT_GRID,
    FIELD_DURATION_S,
    FIELD_TOUCH_TRIALS,
    dense_protocol,
    grid_from_dict,
    grid_to_dict,
    resolve_grid,
    score_fields,
)
from ectskin.electrostatics.reconstruct import normalise_sensitivity
from ectskin.io import write_recording
from ectskin.layout import Region, SensorLayout
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.twin import Protocol, SensorModel, simulate_experiment
from ectskin.twin.ect import ect_grid, sensitivity
from ectskin.twin.field_spec import FieldGrid
from ectskin.twin.protocol import RESPONSES
from ectskin.twin.readout import ReadoutConfig, noise_pf, snr_db

log = logging.getLogger(__name__)

SCORE_FILE = "score.json"
SCORE_FORMAT = 1
TASKS = ("touch", "contact", "track")
#: relative singular value above which a direction of the sensitivity matrix counts as resolved
RANK_THRESHOLD = 1e-2
#: how the touch trials are read by default (``ScoreConfig.response``): from the response
#: fields, measured (paper's layout, 3 seeds): point error 3.10 / 3.39 / 2.59 mm against
#: 9.88 / 8.33 / 16.32 mm solved per dwell (BENCHMARKS.md)
DEFAULT_RESPONSE = "field"


def design_protocol(seed: int = 0, response: str = "solve", **overrides: Any) -> Protocol:
    """The default design protocol (see the module docstring); ``overrides`` set any
    :class:`~ectskin.twin.Protocol` field. ``response="field"``: the field protocol
    (:mod:`ectskin.design.score_field`): :data:`~ectskin.design.score_field.FIELD_TOUCH_TRIALS`
    touch trials of :data:`~ectskin.design.score_field.FIELD_DURATION_S` per state by default,
    read from the states' response fields, the finger at a new point every
    :data:`~ectskin.design.score_field.DWELL_S` (unless ``overrides`` set the dwells)."""
    check_option("response", response, RESPONSES, source="design protocol")
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
    if response == "solve":
        return replace(base, **overrides)
    dense = {"touch_trials": FIELD_TOUCH_TRIALS, "duration_s": FIELD_DURATION_S}
    dense.update({k: v for k, v in overrides.items() if k not in ("touch_dwells", "dwell_slide_s")})
    protocol = dense_protocol(replace(base, **dense))
    own = {k: v for k, v in overrides.items() if k in ("touch_dwells", "dwell_slide_s")}
    return replace(protocol, **own)


@dataclass(frozen=True)
class ScoreConfig:
    """How a layout is scored.

    protocol : the simulated experiment (default :func:`design_protocol` for ``response``).
    epochs : training epochs per task on the ``quick`` profile (assumed small defaults: the
        point is to rank layouts, not to reach the paper's accuracy).
    seed : seeds the split, the models and the protocol's own draws through ``protocol.seed``.
    tasks : which models to train; ``contact`` is required (localisation and force).
    mesh : the twin's mesh for the simulation (:data:`~ectskin.design.information.MESHES`):
        ``coarse`` (default: the information score's mesh, about 5x faster a touch trial than
        the twin's own; the paper's layout, seed 0: 42.71 against 41.87 mm) or ``default`` (the
        twin's own). A mesh other than the twin's own joins :meth:`settings`.
    response : how the touch trials' readouts are computed: ``solve`` (method-of-moments
        solves per dwell, the design protocol) or ``field`` (read from the states' response
        fields, the dense field protocol: :mod:`ectskin.design.score_field`). None: the
        protocol's when one is given, else :data:`DEFAULT_RESPONSE`; a protocol of the other
        reading is an error. ``field`` joins :meth:`settings` with the field grid.
    field_grid : the fields' grid, a name of :data:`~ectskin.twin.field_spec.FIELD_GRIDS`
        (default ``quick``, the reproduction's) or a :class:`~ectskin.twin.field_spec.FieldGrid`;
        held as the grid.
    field_cache : where the fields are cached (default
        :func:`~ectskin.pipeline.field.field_cache_dir`); not a setting (a field's folder is
        named by its key).
    """

    protocol: Protocol | None = None
    epochs: dict[str, int] = field(default_factory=lambda: {"touch": 15, "contact": 6, "track": 3})
    seed: int = 0
    tasks: tuple[str, ...] = TASKS
    region_rows: int = 2
    region_cols: int = 1
    mesh: str = "coarse"
    response: str | None = None
    field_grid: str | FieldGrid = DEFAULT_GRID
    field_cache: str | Path | None = None

    def __post_init__(self) -> None:
        check_option("mesh", self.mesh, tuple(MESHES))
        if self.response is not None:
            check_option("response", self.response, RESPONSES, source="score config")
        if self.protocol is not None and not isinstance(self.protocol, Protocol):
            raise EctskinError(
                f"score config: protocol must be a Protocol, got {type(self.protocol).__name__}"
            )
        response = self.response or (
            self.protocol.response if self.protocol is not None else DEFAULT_RESPONSE
        )
        protocol = self.protocol or design_protocol(response=response)
        if protocol.response != response:
            raise EctskinError(
                f"score config: response {response!r} needs a protocol with response="
                f"{response!r} (design_protocol(response={response!r})), got one with "
                f"{protocol.response!r}"
            )
        object.__setattr__(self, "response", response)
        object.__setattr__(self, "protocol", protocol)
        object.__setattr__(self, "field_grid", resolve_grid(self.field_grid))
        if self.field_cache is not None and not isinstance(self.field_cache, str | Path):
            raise EctskinError(
                f"score config: field_cache must be a folder (str or Path) or None, got "
                f"{type(self.field_cache).__name__}"
            )
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

    @property
    def grid(self) -> FieldGrid:
        """The fields' grid (a :class:`~ectskin.twin.field_spec.FieldGrid` after construction)."""
        assert isinstance(self.field_grid, FieldGrid)
        return self.field_grid

    def settings(self) -> dict[str, Any]:
        """Everything a finished score depends on (compared on resume): the solve reading's
        are those of scores made before the field reading existed."""
        out = {
            "format": SCORE_FORMAT,
            "protocol": self.protocol.to_dict(),  # (set by __post_init__)
            "epochs": {t: self.epochs[t] for t in self.tasks},
            "seed": self.seed,
            "tasks": list(self.tasks),
            "regions": [self.region_rows, self.region_cols],
        }
        if self.mesh != "default":
            out["mesh"] = self.mesh
        if self.response == "field":
            out["response"] = "field"
            out["field_grid"] = grid_to_dict(self.grid)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**self.settings(), "epochs": dict(self.epochs)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ScoreConfig:
        grid = d.get("field_grid")
        return cls(
            protocol=Protocol.from_dict(d["protocol"]),
            epochs={k: int(v) for k, v in d["epochs"].items()},
            seed=int(d["seed"]),
            tasks=tuple(d["tasks"]),
            region_rows=int(d["regions"][0]),
            region_cols=int(d["regions"][1]),
            mesh=str(d.get("mesh", "default")),
            response=str(d.get("response", "solve")),
            field_grid=DEFAULT_GRID if grid is None else grid_from_dict(grid),
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


def scored_layout(layout: SensorLayout, config: ScoreConfig) -> SensorLayout:
    """``layout`` with the scoring regions of ``config`` in place of its own: what is simulated
    (and what the score's response fields are built for)."""
    return replace(layout, regions=scoring_regions(layout, config.region_rows, config.region_cols))


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
    scored = scored_layout(layout, config)
    fields, t_fields = None, None
    if config.response == "field":
        fields, built = score_fields(config.protocol, scored, config.grid, config.field_cache)
        t_fields = built["seconds"]
    rec = simulate_experiment(
        config.protocol,
        layout=scored,
        discretisation=MESHES[config.mesh],
        workers=1,
        progress=False,
        fields=fields,
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
        "seconds": {
            "simulate": t_sim,  # with the fields' build or read (the field reading)
            "fields": t_fields,
            "learn": t_learn,
            "total": time.perf_counter() - t0,
        },
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
    "scored_layout",
    "scoring_regions",
    "sensor_metrics",
]
