"""The information score of a layout: what one frame of its readouts can tell, without training.

Per layout, the Cramér–Rao bound maps of the finger's point (u, v) and force F
(:func:`ectskin.twin.bound.bound_maps`) over a grid of both faces (:func:`~ectskin.twin.bound.skin_grid`
at ``spacing_mm``), for each inflation state of :class:`InformationConfig` (default the chambers
all empty and all at 20 ml), with the nuisances estimated alongside (the hand's push, the
inflation known to ±1 ml, the fingertip's radius to ±1 mm: the bound's ``all`` case). The
readouts come from direct method-of-moments solves on a coarse mesh
(:data:`~ectskin.twin.bound.COARSE`, ``mesh="coarse"``) or the default one.

The maps reduce to (pooled over states, faces and grid points):

* ``bound_mm_mean``, ``bound_mm_p95``: the mean and the 95th percentile ("worst case") of the
  position bound sqrt(var_u + var_v), mm (the mean is inf, null in JSON, when a point is
  unresolved; the percentile when it reaches an unresolved point, :func:`worst_case`);
* ``force_observable_share``: the share of points whose force bound is below
  :data:`~ectskin.twin.bound.FORCE_THRESHOLD_N`;
* ``fit_error_mm_mean``, ``fit_error_mm_p95``, ``fit_error_mm_median``: the same of the position
  error of a fit through a field made with one fingertip (``InformationConfig.fit``, a
  :class:`~ectskin.twin.bound_fit.FitModel`; :func:`~ectskin.twin.bound_fit.fit_error`): it estimates the
  hand's push, the inflation and a scale on the finger's signal
  (:data:`~ectskin.inversion.fit.FINGER_SCALE_SD`, as the inversion does), while the person's
  fingertip radius (±1 mm) and pulp modulus (ln 4 / √12) move the readouts unmodelled. This is
  the bound plus what the fit's model omits, from the same Jacobians (no extra solves beyond the
  pulp's column): a layout whose readouts tell a bigger or softer finger from a shifted one
  scores better on it than on the bound alone;
* ``ambiguity_sigma``: the global ambiguity a local bound misses: the least distance, in noise
  units, between the nominal readouts of two grid points more than ``separation_mm`` apart (points
  on different faces always count as apart), in the same state, least over the states. Two
  points i, j differ by d² = Σ_p (C_ip − C_jp)² / ((σ_ip² + σ_jp²) / 2) with σ the noise of pair p
  at each readout (:func:`~ectskin.twin.readout.noise_pf`): a small d means a frame at one point
  may be read as the other, however small the local bounds are.

Everything runs in one process on one BLAS thread, the points in a fixed order, so a layout's
score is the same number wherever and however often it is computed. :func:`information_layout`
writes ``<dir>/information.json`` (the maps, the summary, the settings) last and atomically and
:func:`finished_information` reads it back when its settings match, so sweeps and searches resume.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError, check_option
from ectskin._files import read_json, to_jsonable, write_json_atomic, write_text_atomic
from ectskin.inversion.fit import FINGER_SCALE_SD
from ectskin.layout import SensorLayout
from ectskin.twin.bound import (
    COARSE,
    DEFAULT_PRIOR_SD,
    FORCE_THRESHOLD_N,
    NUISANCE_NAMES,
    NUISANCES,
    ResponseProvider,
    TwinResponse,
    bound_maps,
    cases,
    skin_grid,
)
from ectskin.twin.bound_fit import FitModel
from ectskin.twin.readout import ReadoutConfig, noise_pf
from ectskin.twin.sensor import Discretisation, SensorModel

INFORMATION_FILE = "information.json"
INFORMATION_FORMAT = 3  # 2: bound_mm_p95 is inf when it reaches an unresolved point; 3: fit_error
#: the fit of the information score's ``fit_error_*`` (module docstring)
DEFAULT_FIT = FitModel(nuisances=("push", "inflation"), left_out=("finger", "modulus"),
                       scale_sd=FINGER_SCALE_SD)
#: the meshes of the readouts' solves
MESHES = {"coarse": COARSE, "default": Discretisation()}
#: the summary's keys, as they join a layout's entry of ``design.json``
SUMMARY_KEYS = (
    "bound_mm_mean",
    "bound_mm_p95",
    "force_observable_share",
    "fit_error_mm_mean",
    "fit_error_mm_p95",
    "fit_error_mm_median",
    "ambiguity_sigma",
    "wire_length_mm",
)


@dataclass(frozen=True)
class InformationConfig:
    """How the information score is computed (see the module docstring).

    states_ml : inflation states (ml per chamber) the maps are made at.
    spacing_mm : the grid's spacing on each face (:func:`~ectskin.twin.bound.skin_grid`).
    force_n : the finger's force at every grid point, N.
    nuisances : estimated alongside (:data:`~ectskin.twin.bound.NUISANCES` by default; any of
        :data:`~ectskin.twin.bound.NUISANCE_NAMES`, the pulp modulus too), with ``prior_sd``.
    mesh : ``coarse`` (:data:`~ectskin.twin.bound.COARSE`, the default) or ``default``.
    separation_mm : two grid points on one face count as distinct beyond this distance.
    fit : the fit whose error gives ``fit_error_*`` (:data:`DEFAULT_FIT`; its left-out
        nuisances take their spread from ``prior_sd``), or None: no such keys.
    """

    states_ml: tuple[tuple[float, ...], ...] = ((0.0, 0.0, 0.0), (20.0, 20.0, 20.0))
    spacing_mm: float = 15.0
    force_n: float = 1.0
    nuisances: tuple[str, ...] = NUISANCES
    prior_sd: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_PRIOR_SD))
    mesh: str = "coarse"
    separation_mm: float = 5.0
    readout: ReadoutConfig = field(default_factory=ReadoutConfig)
    fit: FitModel | None = DEFAULT_FIT

    def __post_init__(self) -> None:
        states = tuple(tuple(float(x) for x in s) for s in self.states_ml)
        if not states or any(
            not s or not all(np.isfinite(x) and x >= 0 for x in s) for s in states
        ):
            raise EctskinError(
                f"information score: states_ml must be one or more states of finite volumes "
                f">= 0 ml per chamber, got {self.states_ml!r}"
            )
        if len(set(states)) != len(states):
            raise EctskinError(f"information score: states_ml repeats a state: {self.states_ml!r}")
        object.__setattr__(self, "states_ml", states)
        object.__setattr__(self, "nuisances", tuple(self.nuisances))
        for name, value in (("spacing_mm", self.spacing_mm), ("force_n", self.force_n)):
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise EctskinError(
                    f"information score: {name} must be a finite number > 0, got {value!r}"
                )
        if not (np.isfinite(self.separation_mm) and self.separation_mm >= 0):
            raise EctskinError(
                f"information score: separation_mm must be a finite number >= 0, got "
                f"{self.separation_mm!r}"
            )
        check_option("mesh", self.mesh, tuple(MESHES))
        for k in self.nuisances:
            check_option("nuisance", k, NUISANCE_NAMES)
        if self.fit is not None:
            if not isinstance(self.fit, FitModel):
                raise EctskinError(
                    f"information score: fit must be a FitModel or None, got {type(self.fit).__name__}"
                )
            missing = [k for k in self.fit.left_out if self.prior_sd.get(k) is None]
            if missing:
                raise EctskinError(
                    f"information score: the fit's left-out nuisances {missing} need their spread "
                    f"in prior_sd (got {sorted(self.prior_sd)})"
                )

    def settings(self) -> dict[str, Any]:
        """Everything a finished score depends on (compared on resume)."""
        return to_jsonable(
            {
                "format": INFORMATION_FORMAT,
                "states_ml": [list(s) for s in self.states_ml],
                "spacing_mm": self.spacing_mm,
                "force_n": self.force_n,
                "nuisances": list(self.nuisances),
                "prior_sd": dict(sorted(self.prior_sd.items())),
                "mesh": self.mesh,
                "separation_mm": self.separation_mm,
                "readout": asdict(self.readout),
                "fit": None if self.fit is None else self.fit.settings(),
            }
        )

    def to_dict(self) -> dict[str, Any]:
        return self.settings()


#: a provider factory: (layout, config) → {state: its ResponseProvider}
Providers = Callable[[SensorLayout, InformationConfig], Mapping[tuple[float, ...], ResponseProvider]]


def twin_providers(
    layout: SensorLayout, config: InformationConfig
) -> dict[tuple[float, ...], ResponseProvider]:
    """Direct solves of the twin (:class:`~ectskin.twin.bound.TwinResponse`) on ``config.mesh``,
    one sensor model shared by the states."""
    sensor = SensorModel(layout, discretisation=MESHES[config.mesh])
    return {s: TwinResponse(sensor, s) for s in config.states_ml}


def wire_length_mm(layout: SensorLayout) -> float:
    """Total length of the electrodes' polylines (wires and their leads), mm."""
    return float(sum(e.length_mm for e in layout.electrodes))


def grid_points(layout: SensorLayout, spacing_mm: float) -> tuple[list[str], np.ndarray]:
    """Faces (N,) and points (N, 2) mm of the grid of every face, in the maps' order (per face,
    row-major with v slow)."""
    faces: list[str] = []
    pts = []
    for face in dict.fromkeys(s.surface for s in layout.skins):
        u, v = skin_grid(layout, face, spacing_mm)
        U, V = np.meshgrid(u, v)
        pts.append(np.c_[U.ravel(), V.ravel()])
        faces += [face] * U.size
    return faces, np.concatenate(pts)


def readout_distances(c: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(N, N) distances in noise units between the readouts ``c`` (N, n_pairs) whose noise is
    ``sigma`` (N, n_pairs): d_ij² = Σ_p (c_ip − c_jp)² / ((σ_ip² + σ_jp²) / 2)."""
    diff = c[:, None, :] - c[None, :, :]
    var = 0.5 * (sigma[:, None, :] ** 2 + sigma[None, :, :] ** 2)
    return np.sqrt(np.sum(diff**2 / var, axis=2))


def apart(faces: Sequence[str], points: np.ndarray, separation_mm: float) -> np.ndarray:
    """(N, N) True where two grid points are distinct: on different faces, or more than
    ``separation_mm`` apart on one."""
    f = np.asarray(faces)
    dist = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    return (f[:, None] != f[None, :]) | (dist > separation_mm)


def ambiguity(
    providers: Mapping[tuple[float, ...], ResponseProvider],
    layout: SensorLayout,
    config: InformationConfig,
) -> dict[str, Any]:
    """The least readout distance (noise units) between distinct grid points, per state and
    overall, with the pair of points that has it (module docstring)."""
    faces, pts = grid_points(layout, config.spacing_mm)
    mask = np.triu(apart(faces, pts, config.separation_mm), k=1)
    if not mask.any():
        raise EctskinError(
            f"information score: no two grid points are more than {config.separation_mm:g} mm "
            f"apart (spacing_mm {config.spacing_mm:g})"
        )
    per_state = []
    best: dict[str, Any] = {"sigma": np.inf}
    for state, provider in providers.items():
        c = np.empty((len(pts), layout.n_pairs))
        for face in dict.fromkeys(faces):
            rows = [i for i, f in enumerate(faces) if f == face]
            n = len(rows)
            c[rows] = provider.readout(face, pts[rows], np.full(n, config.force_n), np.zeros(n))
        d = readout_distances(c, noise_pf(c, config.readout))
        d = np.where(mask, d, np.inf)
        i, j = np.unravel_index(int(np.argmin(d)), d.shape)
        per_state.append(float(d[i, j]))
        if d[i, j] < best["sigma"]:
            best = {
                "sigma": float(d[i, j]),
                "inflation_ml": list(state),
                "points": [
                    {"face": faces[i], "uv_mm": pts[i].tolist()},
                    {"face": faces[j], "uv_mm": pts[j].tolist()},
                ],
            }
    return {"per_state": per_state, **best}


def worst_case(values: np.ndarray, q: float = 95.0) -> float:
    """The ``q``-th percentile of the position bounds ``values`` with unresolved points (inf)
    ranked last: inf when the percentile reaches into them, even in part (linear interpolation
    between the largest finite bound and an inf is inf, not a finite number between)."""
    x = np.asarray(values, dtype=np.float64).ravel()
    finite = np.isfinite(x)
    if finite.all():
        return float(np.percentile(x, q))
    if not finite.any():
        return float("inf")
    top = float(x[finite].max())
    got = float(np.percentile(np.where(finite, x, top + 1.0), q))
    return float("inf") if got > top else got


def _position_bounds(maps: Mapping[str, Any], case: str) -> np.ndarray:
    """Every grid point's position bound (contact mode, ``case``), pooled over states and faces."""
    return np.concatenate([
        np.asarray(face["contact"][case]["position_mm"], dtype=np.float64).ravel()
        for state in maps["states"]
        for face in state["faces"].values()
    ])


def _fit_summary(maps: Mapping[str, Any], config: InformationConfig) -> dict[str, Any]:
    """The ``fit_error_*`` keys (None without a fit): mean (inf with an unresolved point), p95
    (:func:`worst_case`) and median of the fit's position error over every grid point."""
    if config.fit is None:
        return {"fit_error_mm_mean": None, "fit_error_mm_p95": None, "fit_error_mm_median": None}
    x = _position_bounds(maps, "fit")
    return {
        "fit_error_mm_mean": float(np.mean(x)),
        "fit_error_mm_p95": worst_case(x),
        "fit_error_mm_median": maps["summary"]["contact"]["fit"]["position_mm"]["median"],
    }


def information_score(
    layout: SensorLayout,
    config: InformationConfig | None = None,
    *,
    providers: Providers = twin_providers,
) -> dict[str, Any]:
    """The information score of ``layout``: ``summary`` (the keys of :data:`SUMMARY_KEYS`),
    ``maps`` (:func:`~ectskin.twin.bound.bound_maps`, contact mode), ``ambiguity``,
    ``information_seconds`` (wall) and ``information_cpu_seconds`` (this process's CPU time).
    ``providers``: the readouts per state (:func:`twin_providers` by default)."""
    config = config or InformationConfig()
    t0, c0 = time.perf_counter(), time.process_time()
    with threadpool_limits(1):  # one BLAS thread: the same sums wherever the task runs
        states = dict(providers(layout, config))
        maps = bound_maps(
            states,
            layout,
            spacing_mm=config.spacing_mm,
            force_n=config.force_n,
            nuisances=config.nuisances,
            prior_sd=config.prior_sd,
            readout=config.readout,
            force_threshold_n=FORCE_THRESHOLD_N,
            fit=config.fit,
        )
        amb = ambiguity(states, layout, config)
    case = cases(config.nuisances)[-1]  # every nuisance estimated at once
    s = maps["summary"]["contact"][case]
    summary = {
        "bound_mm_mean": s["position_mm"]["mean"],
        # not the maps' own p95: theirs interpolates towards a finite stand-in for inf
        "bound_mm_p95": worst_case(_position_bounds(maps, case)),
        "force_observable_share": s["force_observable_share"],
        **_fit_summary(maps, config),
        "ambiguity_sigma": amb["sigma"],
        "wire_length_mm": wire_length_mm(layout),
    }
    return {
        "name": layout.name,
        "n_electrodes": layout.n_electrodes,
        "n_pairs": layout.n_pairs,
        **summary,
        "case": case,
        "bound_mm_median": s["position_mm"]["median"],
        "resolved_share": s["resolved_share"],
        "ambiguity": amb,
        "maps": maps,
        "information_seconds": time.perf_counter() - t0,
        # this process's CPU time: the cost of the score apart from what else the machine runs
        "information_cpu_seconds": time.process_time() - c0,
    }


def finished_information(
    dir_: str | Path, layout: SensorLayout, config: InformationConfig
) -> dict | None:
    """The information score in ``dir_`` when it was made for this layout and these settings."""
    path = Path(dir_) / INFORMATION_FILE
    if not path.is_file():
        return None
    try:
        score = read_json(path, "information score")
    except EctskinError:
        return None
    ok = (
        isinstance(score, dict)
        and score.get("settings") == config.settings()
        and score.get("layout") == to_jsonable(layout.to_dict())
    )
    return score if ok else None


def information_layout(
    layout: SensorLayout,
    out_dir: str | Path,
    config: InformationConfig | None = None,
    providers: Providers = twin_providers,
) -> dict[str, Any]:
    """Score ``layout`` into ``out_dir/information.json`` (and write its ``layout.json``) unless
    a finished score for this layout with these settings is there; return it as the file holds
    it. The unit of work of the bound objective (one Dask task per layout)."""
    config = config or InformationConfig()
    out = Path(out_dir)
    done = finished_information(out, layout, config)
    if done is not None:
        return done
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "layout.json", layout.to_json() + "\n")
    score = information_score(layout, config, providers=providers)
    score = {**score, "settings": config.settings(), "layout": layout.to_dict()}
    write_json_atomic(out / INFORMATION_FILE, score)
    return to_jsonable(score)


def information_to_dict(score: Mapping[str, Any]) -> dict[str, Any]:
    """The headline fields of an information score (its ``design.json`` entry: no maps)."""
    return {k: v for k, v in score.items() if k not in ("maps", "layout", "settings")}


__all__ = [
    "INFORMATION_FILE",
    "InformationConfig",
    "ambiguity",
    "finished_information",
    "information_layout",
    "information_score",
    "information_to_dict",
    "readout_distances",
    "twin_providers",
    "worst_case",
    "wire_length_mm",
]
