"""The localisation error of training-free ECT images over a recording's touch frames.

For every inflation state among the touch trials one sensitivity (:func:`~ectskin.twin.ect.sensitivity`)
and one reconstruction per method; each sampled contact frame's image is located and compared
with the recording's ground truth over the skin (:func:`~ectskin.layout.geometry.on_skin_distance`),
with the body's size taken from the recording (``meta["manipulator"]``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.electrostatics.reconstruct import (
    DEFAULT_ITERATIONS,
    DEFAULT_LAMBDA,
    DEFAULT_RELAXATION,
    METHODS,
    Reconstructor,
    collapse_layers,
    layer_sum_matrix,
)
from ectskin.io import Recording, require_ground_truth
from ectskin.io.calibration import is_no_contact, touch_reference
from ectskin.layout.geometry import on_skin_distance
from ectskin.twin.ect import LOCALISATIONS, EctGrid, ect_grid, locate, sensitivity
from ectskin.twin.mechanics import Manipulator, recording_manipulator
from ectskin.twin.sensor import SensorModel

log = logging.getLogger(__name__)


def _state_references(rec: Recording) -> dict[tuple, np.ndarray]:
    """Inflation state → mean readout of its no-contact trial(s), pF."""
    by_state: dict[tuple, list[np.ndarray]] = {}
    for t in rec.trials:
        if is_no_contact(t):
            by_state.setdefault(t.inflation, []).append(t.capacitance)
    return {s: np.nanmean(np.concatenate(c), axis=0) for s, c in by_state.items()}


def _pixel_images(
    builder: Reconstructor, pixel_matrix: np.ndarray | None, delta_c: np.ndarray, grid: EctGrid
) -> np.ndarray:
    """Images summed over layers, (n_pix,) or (F, n_pix), of ``delta_c`` (n_pairs,) or (F,
    n_pairs): through the precomputed pixel matrix of a linear method, else reconstructed."""
    if pixel_matrix is not None:
        return delta_c @ pixel_matrix.T
    return collapse_layers(builder.image(delta_c), grid.pixel, grid.n_pixels)


def ect_image_metrics(
    rec: Recording,
    trials: Sequence[str] | None = None,
    *,
    method: str = "tikhonov",
    methods: Sequence[str] = METHODS,
    frame_step: int = 10,
    localisation: str = "centroid",
    sensor: SensorModel | None = None,
    grid: EctGrid | None = None,
    lam: float = DEFAULT_LAMBDA,
    iterations: int = DEFAULT_ITERATIONS,
    relaxation: float = DEFAULT_RELAXATION,
    n_examples: int = 4,
    kind: str = "conductor",
) -> dict:
    """Localisation errors of ECT images on a recording's touch frames, per method.

    For every inflation state among the touch trials one Jacobian (cached); ``Δc`` = frame −
    that state's no-contact mean (falling back to the recording's touch reference,
    :func:`~ectskin.io.calibration.touch_reference`); every ``frame_step``-th frame with one finger
    in contact is imaged and located (a frame where a second finger presses too is left out: one
    located point cannot answer for two, and the learned model's point error is over
    single-contact frames as well) (``localisation``: "peak" or "centroid"); ``kind`` picks the voxel
    sensitivity (:func:`~ectskin.twin.ect.sensitivity`). The error is the distance on the
    face in rest coordinates; a frame located on the wrong face counts as a face error and its
    error is the on-skin distance around the body
    (:func:`~ectskin.layout.geometry.on_skin_distance`). ``sensor``: default the layout on the
    recording's manipulator (``meta["manipulator"]``, else the default body).

    Returns a dict: per method ``loc_mm_mean``, ``loc_mm_median``, ``loc_mm_p90``,
    ``face_accuracy``, ``n_frames``; ``timing`` (``jacobian_s`` per state,
    ``reconstruct_us_per_frame`` per method); ``examples`` (``method``'s images of
    ``n_examples`` touches for :func:`ectskin.viz.plot_ect_images`); ``grid`` (faces, extents).
    """
    require_ground_truth(rec)
    for m in methods:
        check_option("methods", m, METHODS)
    check_option("method", method, METHODS)
    check_option("localisation", localisation, LOCALISATIONS)
    if isinstance(frame_step, bool) or not isinstance(frame_step, int) or frame_step < 1:
        raise EctskinError(f"frame_step must be a positive integer, got {frame_step!r}")
    names = {t.name for t in rec.trials}
    if trials is not None:
        missing = [n for n in trials if n not in names]
        if missing:
            raise EctskinError(f"trials {missing[:3]} are not in the recording")
    wanted = set(names if trials is None else trials)
    touch = [
        t
        for t in rec.trials
        if t.name in wanted
        and t.contact is not None
        and t.n_fingers
        and t.contact[:, 0].any()
        and t.finger_surface[0]  # (finger 0, which the labels follow)
    ]
    if not touch:
        raise EctskinError("ect_image_metrics: no trial with contact frames to evaluate")
    if sensor is None:
        body, source = recording_manipulator(rec.meta)
        if source == "default":
            log.info("the recording names no manipulator: imaging on the default body")
        sensor = SensorModel(rec.layout, Manipulator(body))
    grid = grid or ect_grid(rec.layout)
    w_mm, t_mm = sensor.manipulator.config.width_mm, sensor.manipulator.config.thickness_mm
    state_ref = _state_references(rec)
    fallback: dict[str, np.ndarray] = {}  # the touch reference, read when first needed
    errors: dict[str, list[float]] = {m: [] for m in methods}
    face_ok: dict[str, list[bool]] = {m: [] for m in methods}
    rec_time = {m: [0.0, 0] for m in methods}
    jac_s: dict[str, float] = {}
    examples: list[dict] = []
    example_every = max(1, len(touch) // max(n_examples, 1))
    by_state: dict[tuple, list] = {}
    for t in touch:
        by_state.setdefault(t.inflation, []).append(t)
    for state, ts in by_state.items():
        t0 = time.perf_counter()
        sens = sensitivity(sensor, grid, list(state), kind=kind)
        jac_s[",".join(f"{v:g}" for v in state)] = time.perf_counter() - t0
        ref = state_ref.get(state)
        if ref is None:
            if not fallback:
                fallback = touch_reference(rec)
            log.info("no no-contact trial at %s ml: using the recording's touch reference", state)
        builders = {
            m: Reconstructor.build(
                sens.jacobian,
                m,
                row_scale=ref if ref is not None else sens.readout,
                lam=lam,
                iterations=iterations,
                relaxation=relaxation,
                response_sign=sens.response_sign,
            )
            for m in methods
        }
        L = layer_sum_matrix(grid.pixel, grid.n_pixels)
        pix_mats = {m: None if r.matrix is None else L @ r.matrix for m, r in builders.items()}
        for t in ts:
            c0 = ref if ref is not None else fallback[t.name]
            single = t.contact[:, 0] & (t.n_contacts == 1)  # finger 0 alone on the skin
            idx = np.flatnonzero(single)[::frame_step]
            idx = idx[np.all(np.isfinite(t.capacitance[idx]), axis=1)]
            if idx.size == 0:
                continue
            dc = t.capacitance[idx] - c0[None, :]
            true_face = t.finger_surface[0]
            for m, r in builders.items():
                t1 = time.perf_counter()
                img = _pixel_images(r, pix_mats[m], dc, grid)
                rec_time[m][0] += time.perf_counter() - t1
                rec_time[m][1] += idx.size
                for row, k in zip(img, idx):
                    f, uv, _ = locate(row, grid, localisation)
                    face = grid.faces[f]
                    d = on_skin_distance(face, uv, true_face, t.finger_uv_mm[k, 0], w_mm, t_mm)
                    errors[m].append(float(d))
                    face_ok[m].append(face == true_face)
            if (
                method in builders
                and len(examples) < n_examples
                and (touch.index(t) % example_every == 0)
            ):
                k = idx[idx.size // 2]
                row = _pixel_images(builders[method], pix_mats[method], t.capacitance[k] - c0, grid)
                f, uv, _ = locate(row, grid, localisation)
                examples.append(
                    {
                        "trial": t.name,
                        "frame": int(k),
                        "images": grid.face_images(row),
                        "true": (true_face, *map(float, t.finger_uv_mm[k, 0])),
                        "pred": (grid.faces[f], float(uv[0]), float(uv[1])),
                    }
                )
    out: dict = {}
    for m in methods:
        e = np.asarray(errors[m])
        out[m] = {
            "loc_mm_mean": float(e.mean()) if e.size else float("nan"),
            "loc_mm_median": float(np.median(e)) if e.size else float("nan"),
            "loc_mm_p90": float(np.percentile(e, 90)) if e.size else float("nan"),
            "face_accuracy": float(np.mean(face_ok[m])) if e.size else float("nan"),
            "n_frames": int(e.size),
        }
    out["timing"] = {
        "jacobian_s": jac_s,
        "reconstruct_us_per_frame": {
            m: 1e6 * rec_time[m][0] / max(rec_time[m][1], 1) for m in methods
        },
    }
    out["examples"] = examples
    out["grid"] = {"faces": list(grid.faces), "extents": [list(e) for e in grid.extents]}
    out["settings"] = {
        "method": method,
        "localisation": localisation,
        "frame_step": frame_step,
        "lam": lam,
        "iterations": iterations,
        "relaxation": relaxation,
        "pixel_mm": grid.pixel_mm,
        "kind": kind,
    }
    return out
