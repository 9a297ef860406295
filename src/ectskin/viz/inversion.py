"""Figures of the training-free inversion: frames with two fingers on the skin as it reads them.

MNE style like :mod:`ectskin.viz.learning`: the function takes plain arrays and ``show=False``
and returns the :class:`matplotlib.figure.Figure`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.viz.learning import _finish, _new_figure

#: colours of a frame's two true fingers (open circles, numbered)
TRUE_COLOURS = ("tab:blue", "tab:green")


def plot_two_finger_examples(
    true_face: Any,
    true_uv: Any,
    fit_face: Any,
    fit_uv: Any,
    fit_contact: Any,
    fit_height: Any,
    faces: Sequence[str],
    face_extent: Mapping[str, Any],
    *,
    wires: Mapping[str, Sequence[Any]] | None = None,
    titles: Sequence[str] | None = None,
    show: bool = False,
):
    """Frames with two fingers on the skin, each as the fit reads them: one panel per frame and
    face (u across, v up), the face's outline and its wires, the true fingers as numbered open
    circles and the fitted ones as a red × where it presses and an orange + with its height
    (mm) where it hovers.

    ``true_face`` (n, 2) int: each true finger's face (an index in ``faces``; < 0: none),
    ``true_uv`` (n, 2, 2) mm; ``fit_face`` (n, S) str (empty: no finger in the slot),
    ``fit_uv`` (n, S, 2) mm, ``fit_contact`` (n, S) bool, ``fit_height`` (n, S) mm, the
    arrays of :func:`ectskin.inversion.results_to_arrays`. ``face_extent``: {face: ((u_lo,
    u_hi), (v_lo, v_hi))} mm; ``wires``: {face: [(k, 2) polyline in (u, v) mm]}; ``titles``:
    one per frame.
    """
    tf, tuv = np.asarray(true_face), np.asarray(true_uv, float)
    ff, fuv = np.asarray(fit_face).astype(str), np.asarray(fit_uv, float)
    fc, fh = np.asarray(fit_contact, bool), np.asarray(fit_height, float)
    n = tf.shape[0] if tf.ndim else 0
    if n == 0:
        raise EctskinError("plot_two_finger_examples: no frame given")
    if tf.shape != (n, 2) or tuv.shape != (n, 2, 2):
        raise EctskinError(
            f"plot_two_finger_examples: true_face must be (n, 2) and true_uv (n, 2, 2), got "
            f"{tf.shape} and {tuv.shape}"
        )
    s = ff.shape[1] if ff.ndim == 2 else 0
    if ff.shape != (n, s) or fuv.shape != (n, s, 2) or fc.shape != (n, s) or fh.shape != (n, s):
        raise EctskinError(
            f"plot_two_finger_examples: fit_face, fit_contact, fit_height must be (n, S) and "
            f"fit_uv (n, S, 2) with n = {n}, got {ff.shape}, {fc.shape}, {fh.shape}, {fuv.shape}"
        )
    missing = [f for f in faces if f not in face_extent]
    if not faces or missing:
        raise EctskinError(
            f"plot_two_finger_examples: every face needs its extent; faces {list(faces)}, "
            f"extents of {sorted(face_extent)}"
        )
    if titles is not None and len(titles) != n:
        raise EctskinError(f"plot_two_finger_examples: {len(titles)} titles for {n} frames")
    nf = len(faces)
    fig = _new_figure(show, figsize=(1.55 * n * nf + 0.6, 5.6), layout="constrained")
    ax = np.asarray(fig.subplots(1, n * nf, squeeze=False, sharey=True))[0]
    for i in range(n):
        for j, face in enumerate(faces):
            a = ax[i * nf + j]
            (u0, u1), (v0, v1) = face_extent[face]
            a.plot([u0, u1, u1, u0, u0], [v0, v0, v1, v1, v0], color="k", lw=0.8)
            for wire in (wires or {}).get(face, []):
                w = np.asarray(wire, float)
                a.plot(w[:, 0], w[:, 1], color="0.55", lw=1.0)
            for k in range(2):
                if tf[i, k] == j:
                    a.plot(*tuv[i, k], "o", ms=9, mfc="none", mew=1.6, color=TRUE_COLOURS[k])
                    a.annotate(str(k + 1), tuv[i, k], xytext=(6, 6), textcoords="offset points",
                               fontsize=7, color=TRUE_COLOURS[k])
            for k in range(s):
                if ff[i, k] != face or not np.isfinite(fuv[i, k]).all():
                    continue
                if fc[i, k]:
                    a.plot(*fuv[i, k], "x", ms=8, mew=1.8, color="tab:red")
                else:
                    a.plot(*fuv[i, k], "+", ms=9, mew=1.6, color="tab:orange")
                    a.annotate(f"{fh[i, k]:.0f} mm", fuv[i, k], xytext=(5, -10),
                               textcoords="offset points", fontsize=7, color="tab:orange")
            a.set_aspect("equal")
            a.set_xlim(u0 - 3, u1 + 3)
            a.set_title(f"{titles[i]}\n{face}" if titles is not None and j == 0 else face,
                        fontsize=7)
            a.tick_params(labelsize=6)
    ax[0].set_ylabel("v (mm)")
    fig.supxlabel("u (mm); true fingers: numbered circles; fitted: × pressing, + hovering",
                  fontsize=8)
    return _finish(fig, show)
