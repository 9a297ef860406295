"""Figures of the contact task: error map over each face, force scatter (plain, or with each
frame's predicted σ and whether the bound says force is observable there), hover detection curve.

MNE style like :mod:`ectskin.viz.learning`: each function takes plain arrays and ``show=False``
and returns the :class:`matplotlib.figure.Figure`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.viz.learning import _finish, _new_figure

#: the parts of :func:`plot_force_sigma` with a bound: (name, colour, legend text; ``{thr}`` the
#: threshold in N, ``{by}`` what is split: the bound, or the fit's own σ), as
#: :func:`ectskin.learn.metrics.contact.force_split` names them
FORCE_PARTS = (
    ("observable", "tab:green", "observable ({by} < {thr:g} N)"),
    ("not_observable", "tab:red", "not observable ({by} ≥ {thr:g} N)"),
    ("no_bound", "tab:gray", "no {by}"),
)


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


def force_coverage_counts(
    true_n: np.ndarray, pred_n: np.ndarray, sigma_n: np.ndarray
) -> tuple[int, int, int]:
    """(frames with a finite σ > 0, those with |pred − true| ≤ 1σ, those within 2σ): the counts
    behind :func:`ectskin.learn.metrics.contact.force_coverage`."""
    t, p, s = (np.asarray(a, float) for a in (true_n, pred_n, sigma_n))
    ok = np.isfinite(s) & (s > 0)
    z = np.abs(p[ok] - t[ok]) / s[ok]
    return int(ok.sum()), int(np.sum(z <= 1.0)), int(np.sum(z <= 2.0))


def plot_force_sigma(
    true_n: Any,
    pred_n: Any,
    sigma_n: Any,
    bound_sd_n: Any = None,
    *,
    threshold_n: float = 0.1,
    split_by: str = "bound",
    max_points: int = 400,
    axes: Any = None,
    show: bool = False,
):
    """Predicted against true force (N), each frame with its predicted σ as a ±1σ error bar,
    coloured by whether force is observable there.

    ``true_n``, ``pred_n``, ``sigma_n`` (n,) N: the frames with one finger on the skin, the
    model's force and its standard deviation (NaN or ≤ 0: none; such a frame is drawn as a hollow
    marker without a bar). ``bound_sd_n`` (n,) N: the Cramér–Rao bound on the force's standard
    deviation at each frame's true point (NaN: none); frames whose bound is below
    ``threshold_n`` are *observable*, those at or above it *not observable*, the rest *no bound*
    (:data:`FORCE_PARTS`); None: one part, all frames. ``split_by``: what ``bound_sd_n`` is, as
    the legend names it ("bound"; an inversion's split by its own standard error: "σ"). The
    legend gives per part its frames
    and the share of those with a σ whose true force lies within ±1σ and ±2σ of the prediction
    (a calibrated Gaussian σ covers 68.3 % and 95.4 %), over every frame of the part; at most
    ``max_points`` frames (evenly spaced) are drawn. ``axes``: where to draw (a new figure
    otherwise)."""
    t, p, s = (np.asarray(a, float) for a in (true_n, pred_n, sigma_n))
    b = np.full(t.shape, np.nan) if bound_sd_n is None else np.asarray(bound_sd_n, float)
    if t.ndim != 1 or not t.shape == p.shape == s.shape == b.shape:
        raise EctskinError(
            "plot_force_sigma: true_n, pred_n, sigma_n and bound_sd_n must be one-dimensional of "
            f"one shape, got {t.shape}, {p.shape}, {s.shape}, {b.shape}"
        )
    if not (isinstance(threshold_n, int | float) and np.isfinite(threshold_n) and threshold_n > 0):
        raise EctskinError(
            f"plot_force_sigma: threshold_n must be a number > 0, got {threshold_n!r}"
        )
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 1:
        raise EctskinError(
            f"plot_force_sigma: max_points must be an integer >= 1, got {max_points!r}"
        )
    if bound_sd_n is None:
        parts = [("all", "tab:blue", "test frames", np.ones(t.shape, bool))]
    else:
        has = np.isfinite(b)
        masks = {
            "observable": has & (b < threshold_n),
            "not_observable": has & ~(b < threshold_n),
            "no_bound": ~has,
        }
        parts = [(n, c, text.format(thr=threshold_n, by=split_by), masks[n])
                 for n, c, text in FORCE_PARTS]
    drawn = np.zeros(t.shape, bool)  # the frames drawn: at most max_points, evenly spaced
    drawn[np.linspace(0, t.size - 1, min(t.size, max_points)).astype(int)] = True
    if axes is None:
        fig = _new_figure(show, figsize=(5.4, 6.0), layout="constrained")
        ax = fig.subplots()
    else:
        ax, fig = axes, axes.figure
    has_sigma = np.isfinite(s) & (s > 0)
    handles: list[Any] = []
    for name, colour, text, m in parts:
        if not m.any():
            continue
        n_sigma, n1, n2 = force_coverage_counts(t[m], p[m], s[m])
        n = int(m.sum())
        label = f"{text}, {n} frame{'' if n == 1 else 's'}: "
        if n_sigma:
            label += f"±1σ {100 * n1 / n_sigma:.1f} %, ±2σ {100 * n2 / n_sigma:.1f} %"
        else:
            label += "no σ"
        if 0 < n_sigma < n:
            label += f" ({n - n_sigma} without σ)"
        bars = m & drawn & has_sigma
        bare = m & drawn & ~has_sigma
        if bars.any():
            eb = ax.errorbar(
                t[bars],
                p[bars],
                yerr=s[bars],
                fmt="o",
                ms=2.5,
                color=colour,
                ecolor=colour,
                elinewidth=0.5,
                alpha=0.45,
                capsize=0,
                label=label,
            )
            for artist in (eb.lines[0], *eb.lines[2]):
                artist.set_gid(name)  # the part, for readers of the figure
            handles.append(eb)
        if bare.any():
            (line,) = ax.plot(
                t[bare],
                p[bare],
                "o",
                ms=3,
                mfc="none",
                color=colour,
                alpha=0.7,
                label=label,
                gid=name,
            )
            if not bars.any():
                handles.append(line)
    finite = np.concatenate([t[np.isfinite(t)], p[np.isfinite(p)]])
    lo = min(0.0, float(finite.min())) if finite.size else 0.0
    hi = max(float(finite.max()) if finite.size else 1.0, 1e-3) * 1.05
    handles += ax.plot([lo, hi], [lo, hi], color="k", lw=0.8, label="exact")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("true force (N)")
    ax.set_ylabel("predicted force ± 1σ (N)")
    title = "share within ±1σ / ±2σ (Gaussian: 68.3 / 95.4 %)"
    if drawn.sum() < t.size:
        title += f"; {int(drawn.sum())} of {t.size} frames drawn"
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(0.0, -0.12),
        fontsize=7,
        title=title,
        title_fontsize=7,
    )
    return _finish(fig, show)
