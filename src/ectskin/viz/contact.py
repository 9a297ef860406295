"""Figures of the contact task: error map over each face, force scatter, hover detection curve.

MNE style like :mod:`ectskin.viz.learning`: each function takes plain arrays and ``show=False``
and returns the :class:`matplotlib.figure.Figure`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ectskin.viz.learning import _finish, _new_figure


def plot_error_maps(
    maps: Mapping[str, Mapping[str, Any]],
    face_extent: Mapping[str, Any],
    *,
    show: bool = False,
):
    """Mean localisation error per cell of each face (``maps[face]``: ``u_edges``, ``v_edges``,
    ``mean_mm`` (nv, nu), ``count``), one panel per face, u across and v (base → tip) up."""
    faces = list(maps)
    fig = _new_figure(show, figsize=(3.2 * max(len(faces), 1) + 1.0, 5.0), layout="constrained")
    axes = fig.subplots(1, max(len(faces), 1), squeeze=False)[0]
    finite = [np.asarray(m["mean_mm"], float) for m in maps.values()]
    vmax = max((np.nanmax(a) for a in finite if np.isfinite(a).any()), default=1.0)
    image = None
    for ax, face in zip(axes, faces):
        m = maps[face]
        grid = np.asarray(m["mean_mm"], float)
        image = ax.pcolormesh(
            np.asarray(m["u_edges"]),
            np.asarray(m["v_edges"]),
            np.ma.masked_invalid(grid),
            cmap="viridis",
            vmin=0.0,
            vmax=vmax,
        )
        (u0, u1), (v0, v1) = face_extent[face]
        ax.plot([u0, u1, u1, u0, u0], [v0, v0, v1, v1, v0], color="k", lw=0.8)
        ax.set_aspect("equal")
        ax.set_title(f"{face} face")
        ax.set_xlabel("u = x (mm)")
    axes[0].set_ylabel("v = z from the base (mm)")
    if image is not None:
        fig.colorbar(image, ax=list(axes), label="mean error (mm)")
    return _finish(fig, show)


def plot_force_scatter(
    true_n: np.ndarray, pred_n: np.ndarray, *, show: bool = False, max_points: int = 5000
):
    """Predicted against true force (N) with the identity line; at most ``max_points`` frames
    (evenly spaced) are drawn."""
    t, p = np.asarray(true_n, float), np.asarray(pred_n, float)
    if t.size > max_points:
        idx = np.linspace(0, t.size - 1, max_points).astype(int)
        t, p = t[idx], p[idx]
    fig = _new_figure(show, figsize=(4.2, 4.0), layout="constrained")
    ax = fig.subplots()
    ax.scatter(t, p, s=3, alpha=0.3, color="tab:red", label="test frames")
    hi = float(max(t.max() if t.size else 1.0, p.max() if p.size else 1.0)) * 1.05
    ax.plot([0, hi], [0, hi], color="k", lw=0.8, label="exact")
    ax.set_xlim(0, hi)
    ax.set_ylim(0, hi)
    ax.set_xlabel("true force (N)")
    ax.set_ylabel("predicted force (N)")
    ax.legend(loc="upper left")
    return _finish(fig, show)


def plot_hover_curve(curve: Mapping[str, Sequence[Any]], threshold: float, *, show: bool = False):
    """Detection rate of a hovering finger per height bin (``curve``: ``edges_mm``, ``rate``
    with None for empty bins) and the rate ``threshold`` that defines the detection height."""
    edges = np.asarray(curve["edges_mm"], float)
    rate = np.array([np.nan if r is None else r for r in curve["rate"]], float)
    fig = _new_figure(show, figsize=(4.8, 3.4), layout="constrained")
    ax = fig.subplots()
    mid = 0.5 * (edges[:-1] + edges[1:])
    ax.plot(mid, rate, "o-", color="tab:blue", label="detected")
    ax.axhline(threshold, color="k", ls="--", lw=0.8, label=f"{threshold:.0%}")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("finger height above the skin (mm)")
    ax.set_ylabel("hover detection rate")
    ax.legend(loc="lower left")
    return _finish(fig, show)
