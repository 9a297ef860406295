"""The inversion step's answers: ContactNet's prediction columns, the two-finger score, the file of
every inverted frame and the figures.

::

    inversion   OUT_DIR/inversion/fits.npz            every inverted test frame: its trial, frame
                                                      and truth, and the fit
                                                      (:func:`ectskin.inversion.results_to_arrays`)
                OUT_DIR/inversion/error_vs_bound.<fmt>  the inversion's point error map beside
                                                      the bound's map per face (the bound step's)
                OUT_DIR/inversion/force_sigma.<fmt>   fitted against true force, each with its
                                                      standard error
                OUT_DIR/inversion/two_fingers.<fmt>   frames with two fingers on the skin as the
                                                      fit reads them

:func:`prediction_columns` puts the fit's answers in the columns of ContactNet's predictions so
that the same functions score both; :func:`write_answers` writes the file and the figures
(:data:`~ectskin.pipeline.metrics.INVERSION_FIGURES`, copied into OUT_DIR/figures by
:func:`~ectskin.pipeline.metrics.copy_figures`).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._files import atomic_write, read_json, save_figure_atomic
from ectskin.learn.data.contact import HOVER_MAX_MM, MAX_FINGERS, ContactData
from ectskin.learn.metrics.contact import multi_metrics
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.learn.tasks.contact import contact_report, slot_points
from ectskin.pipeline.bound import state_key
from ectskin.viz import figure_file
from ectskin.viz.bound import plot_error_vs_bound
from ectskin.viz.contact import plot_force_sigma
from ectskin.viz.inversion import plot_two_finger_examples

FITS_FILE = "fits.npz"
#: frames with two fingers on the skin drawn (evenly spread over those scored)
TWO_FINGER_EXAMPLES = 4


def prediction_columns(arrays: Mapping[str, np.ndarray], faces: Sequence[str],
                       extent: Mapping[str, Any]) -> np.ndarray:
    """The inversion's answers (:func:`ectskin.inversion.results_to_arrays`, F frames) as
    ContactNet's prediction array (F, 3 + S · 5) (:data:`~ectskin.learn.models.contact.
    PRED_COLUMNS`, then per slot :data:`~ectskin.learn.models.contact.SLOT_COLUMNS`).

    ``count``: the fitted fingers that press; ``p_contact``: 1 when one does; ``p_hover``: 1
    when none presses and one hovers at most ``HOVER_MAX_MM`` high. The pressing fingers take
    the slots first, the best-located first (the least point standard error of the readout
    noise, ``point_se_noise_mm`` where given: a two-finger fit's phantom, where the readouts
    hardly tell a point, must not stand for the finger on the skin), then the hovering ones,
    the lowest first; a frame where none presses gives slot 0 the point of the lowest hovering
    finger (the nearest to touching), or, with no finger at all, the middle of the first face
    (an answer is needed wherever a finger is on the skin, and that one is charged its full
    error).
    ``sigma_mm``: the point's standard error, √(σ_u² + σ_v²); ``force_sigma_n``: the force's
    (0 where there is none: no force fitted); ``face``: the index in ``faces``.
    """
    n = len(arrays["n_fingers"])
    S, nc = MAX_FINGERS, len(SLOT_COLUMNS)
    pred = np.zeros((n, len(PRED_COLUMNS) + S * nc))
    (u0, u1), (v0, v1) = extent[faces[0]]
    col = {name: i for i, name in enumerate(SLOT_COLUMNS)}
    face_of = {f: i for i, f in enumerate(faces)}
    # the readout noise's point standard errors (a model error's grows most for large signals);
    # +inf where the fit gave none (it sorts last)
    located = (np.asarray(arrays["point_se_noise_mm"], dtype=np.float64)
               if "point_se_noise_mm" in arrays else np.hypot(*np.moveaxis(arrays["uv_se_mm"], -1, 0)))
    located = np.where(np.isfinite(located), located, np.inf)
    for i in range(n):
        fitted = [k for k in range(S) if arrays["face"][i, k]]
        # the best-located press first: a two-finger fit's phantom (a finger where the readouts
        # hardly tell its point, beyond the wire ends) never stands for the finger on the skin
        pressing = sorted((k for k in fitted if arrays["contact"][i, k]),
                          key=lambda k: located[i, k])
        hovering = sorted((k for k in fitted if not arrays["contact"][i, k]),
                          key=lambda k: arrays["height_mm"][i, k])  # the lowest first
        pred[i, 0] = len(pressing)
        pred[i, 1] = float(bool(pressing))
        pred[i, 2] = float(not pressing and any(
            arrays["height_mm"][i, k] <= HOVER_MAX_MM for k in hovering))
        order = (pressing + hovering)[:S]
        for slot in range(S):
            a = len(PRED_COLUMNS) + slot * nc
            if slot < len(order):
                k = order[slot]
                uv, se = arrays["uv_mm"][i, k], arrays["uv_se_mm"][i, k]
                pred[i, a + col["face"]] = face_of.get(str(arrays["face"][i, k]), 0)
                pred[i, a + col["u_mm"]], pred[i, a + col["v_mm"]] = uv
                pred[i, a + col["sigma_mm"]] = float(np.hypot(*se))
                pred[i, a + col["force_n"]] = (arrays["force_n"][i, k]
                                               if arrays["contact"][i, k] else 0.0)
                if "force_sigma_n" in col and "force_se_n" in arrays and arrays["contact"][i, k]:
                    se_f = float(arrays["force_se_n"][i, k])  # the fit's Fisher standard error
                    pred[i, a + col["force_sigma_n"]] = se_f if np.isfinite(se_f) else 0.0
            else:
                pred[i, a + col["u_mm"]] = (u0 + u1) / 2
                pred[i, a + col["v_mm"]] = (v0 + v1) / 2
                pred[i, a + col["sigma_mm"]] = np.nan
    return pred



def two_finger_rows(data: ContactData, skip: np.ndarray, limit: int | None) -> np.ndarray:
    """Rows of ``data`` with two fingers on the skin that are not in ``skip``, at most ``limit``
    evenly spread (in order)."""
    rows = np.setdiff1d(np.flatnonzero(data.count == 2), skip)
    if limit is not None and rows.size > limit:
        rows = rows[np.unique(np.linspace(0, rows.size - 1, limit).round().astype(int))]
    return rows



def two_finger_score(data: ContactData, arrays: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The count and the per-finger point error of frames with two fingers on the skin (``data``:
    those frames only, every one inverted, in order): ``count_accuracy``, ``count_predicted``
    (how many frames were counted 0, 1 and 2 fingers), the point error of each finger after
    matching where two were counted (``loc_mm_*``, ``n_fingers``:
    :func:`~ectskin.learn.metrics.contact.multi_metrics`), the count accuracy per trial (a
    trial's frames are one pair of fingers' moves, not independent draws) and per inflation
    state (``by_state``: {"0/0/20 ml": {"count_accuracy", "n_frames", "n_trials"}}, the names
    of the contact metrics' ``per_state``; the misses gather in a few states)."""
    pred = prediction_columns(arrays, data.faces, data.face_extent)
    *_, true_pts, pred_pts = slot_points(data, pred)
    count = pred[:, PRED_COLUMNS.index("count")].astype(int)
    multi = multi_metrics(data.count, count, true_pts, pred_pts, MAX_FINGERS)
    right = count == data.count
    per_trial = {data.group_names[g]: float(right[data.group == g].mean())
                 for g in np.unique(data.group)}
    by_state = {}
    for s in np.unique(data.state):
        rows = data.state == s
        by_state[state_key(data.states[int(s)])] = {
            "count_accuracy": float(right[rows].mean()), "n_frames": int(rows.sum()),
            "n_trials": int(np.unique(data.group[rows]).size)}
    return {
        "count_accuracy": multi["count_accuracy"],
        "count_predicted": np.bincount(np.clip(count, 0, MAX_FINGERS),
                                       minlength=MAX_FINGERS + 1).tolist(),
        **{k: multi[k] for k in ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "n_fingers")},
        "n_frames": int(data.n_samples), "n_trials": len(per_trial),
        "count_accuracy_by_trial": per_trial, "by_state": by_state,
    }


def save_fits(path: Path, data: ContactData, rows: np.ndarray, arrays: Mapping[str, np.ndarray],
              spread: np.ndarray) -> Path:
    """Write the fits ``arrays`` of the frames ``rows`` of ``data`` to ``path`` (.npz, atomic):
    ``trial`` and ``frame`` name each frame, ``state`` its inflation (ml), ``spread`` whether it
    is one of the evenly spread test frames (the rest: extra frames with two fingers on the
    skin); ``true_count``, ``true_face`` (an index in ``faces``; < 0: no finger),
    ``true_uv_mm``, ``true_force_n``, ``true_height_mm`` the truth; ``fit_<key>`` each array of
    :func:`ectskin.inversion.results_to_arrays`."""
    out = {
        "trial": np.asarray(data.group_names, dtype=str)[data.group[rows]],
        "frame": np.asarray(data.frame[rows], np.int64),
        "state": np.asarray(data.states, float)[data.state[rows]],
        "spread": np.asarray(spread, bool),
        "faces": np.asarray(data.faces, dtype=str),
        "true_count": data.count[rows], "true_face": data.face[rows], "true_uv_mm": data.uv[rows],
        "true_force_n": data.force[rows], "true_height_mm": data.height[rows],
        **{f"fit_{k}": np.asarray(v) for k, v in arrays.items()},
    }

    def write(fh: Any) -> None:
        buf = io.BytesIO()
        np.savez(buf, **out)
        fh.write(buf.getvalue())

    return atomic_write(path, write, what="the inversion's fits")


def write_answers(out_dir: Path, data: ContactData, rows: np.ndarray,
                  arrays: Mapping[str, np.ndarray], spread: np.ndarray, *,
                  bound_file: Path | None, threshold_n: float, figure_format: str = "png",
                  dpi: int = 150) -> list[str]:
    """Write :data:`FITS_FILE` and the figures (module docstring) into ``out_dir``: the frames
    ``rows`` of ``data`` (every one inverted, in order) and their fits ``arrays``; ``spread``
    (bool, one per row): the evenly spread test frames, whose error map and forces are drawn.
    The frames with two fingers on the skin among all give :data:`TWO_FINGER_EXAMPLES`
    examples. ``bound_file``: the bound step's bound.json; the error map is drawn beside its
    maps where it exists. ``threshold_n``: force is observable where its standard error is
    below it. Returns the names of the files written."""
    spread = np.asarray(spread, bool)
    written = [save_fits(out_dir / FITS_FILE, data, rows, arrays, spread).name]

    def save(fig: Any, stem: str) -> None:
        written.append(save_figure_atomic(fig, out_dir / figure_file(stem, figure_format),
                                          dpi=dpi).name)

    sub = data.take(rows[spread])
    fits = {k: np.asarray(v)[spread] for k, v in arrays.items()}
    pred = prediction_columns(fits, sub.faces, sub.face_extent)
    maps = read_json(bound_file, "bound maps") if bound_file and bound_file.is_file() else None
    error_map = contact_report(sub, pred, with_maps=True).get("map")
    if maps is not None and error_map:
        save(plot_error_vs_bound(error_map, maps, case=maps.get("headline_case", "all")),
             "error_vs_bound")
    one = sub.count == 1
    if one.any():
        a = len(PRED_COLUMNS)
        force, sigma = (pred[one, a + SLOT_COLUMNS.index(c)] for c in ("force_n", "force_sigma_n"))
        save(plot_force_sigma(sub.force[one, 0], force, sigma, sigma, threshold_n=threshold_n,
                              split_by="σ"), "force_sigma")
    two = np.flatnonzero(data.count[rows] == 2)
    if two.size:
        pick = two[np.unique(np.linspace(0, two.size - 1, TWO_FINGER_EXAMPLES).round().astype(int))]
        r = rows[pick]
        titles = [f"{data.group_names[data.group[i]]}\nframe {data.frame[i]}, fitted "
                  f"{int(np.sum(np.asarray(arrays['contact'])[k]))} pressing"
                  for i, k in zip(r, pick)]
        save(plot_two_finger_examples(
            data.face[r, :2], data.uv[r, :2], np.asarray(arrays["face"])[pick],
            np.asarray(arrays["uv_mm"])[pick], np.asarray(arrays["contact"])[pick],
            np.asarray(arrays["height_mm"])[pick], data.faces, data.face_extent,
            wires=(maps or {}).get("wires"), titles=titles), "two_fingers")
    return written
