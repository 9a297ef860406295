"""Figures of the learning results: Fig. 7 confusion map, Fig. 9 tracking examples, Fig. 10 one
marker's trajectory, and training curves.

MNE style: each function takes ``axes=None, show=False`` and returns the
:class:`matplotlib.figure.Figure`; it never decides where files go. Figures are drawn on the Agg
canvas unless ``show=True`` (then through pyplot, to open a window).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from ectskin._check import EctskinError, check_array

#: Colours of the paper's Fig. 9 / Fig. 10: estimated markers red, ground truth blue.
COLOR_EST = "tab:red"
COLOR_TRUE = "tab:blue"


def _new_figure(show: bool, **kwargs: Any) -> Figure:
    if show:
        import matplotlib.pyplot as plt

        return plt.figure(**kwargs)
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def _finish(fig: Figure, show: bool) -> Figure:
    if show:
        import matplotlib.pyplot as plt

        plt.show()
    return fig


def plot_confusion(
    confusion: Any,
    *,
    class_names: Sequence[str] | None = None,
    annotate: bool = True,
    title: str | None = None,
    axes: Any = None,
    show: bool = False,
) -> Figure:
    """Fig. 7: the confusion map, rows = true class, columns = predicted class, counts annotated.

    Parameters
    ----------
    confusion : (n_classes, n_classes) int
        Frame counts (from :func:`ectskin.learn.evaluate.confusion_matrix`).
    class_names : list of str, optional
        Tick labels; default ``"none"`` for class 0 and the region number for the others.
    annotate : bool
        Write the count in each non-zero cell (empty cells stay blank), in a font sized to the
        cell (:func:`cell_font_size`).
    axes : matplotlib Axes, optional
        Where to draw; a new figure otherwise.

    Colours use a logarithmic scale so that a handful of misclassified frames stay visible next
    to diagonal cells of hundreds of frames; empty cells are white.
    """
    conf = check_array("confusion", confusion, (None, None), dtype=np.int64)
    n = conf.shape[0]
    if conf.shape[1] != n:
        raise EctskinError(f"confusion must be square, got shape {conf.shape}")
    names = (
        list(class_names) if class_names is not None else ["none"] + [str(k) for k in range(1, n)]
    )
    if len(names) != n:
        raise EctskinError(f"class_names has {len(names)} names for {n} classes")
    if axes is None:
        size = max(4.0, 0.42 * n + 1.6)
        fig = _new_figure(show, figsize=(size + 1.0, size), layout="constrained")
        ax = fig.add_subplot()
    else:
        ax, fig = axes, axes.figure
    masked = np.ma.masked_equal(conf, 0)
    vmax = max(int(conf.max()), 2)
    im = ax.imshow(masked, cmap="Blues", norm=LogNorm(vmin=1, vmax=vmax), interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.8, label="frames")
    tick_fs = 9 if n <= 12 else 8
    ax.set_xticks(range(n), names, rotation=90 if n > 12 else 0, fontsize=tick_fs)
    ax.set_yticks(range(n), names, fontsize=tick_fs)
    ax.set_xlabel("predicted class")
    ax.set_ylabel("true class")
    # light grid between cells
    ax.set_xticks(np.arange(-0.5, n, 1), minor=True)
    ax.set_yticks(np.arange(-0.5, n, 1), minor=True)
    ax.grid(which="minor", color="0.9", linewidth=0.5)
    ax.tick_params(which="minor", length=0)
    if annotate and conf.any():
        fs = cell_font_size(ax, n, len(str(int(conf.max()))))
        for i, j in zip(*np.nonzero(conf)):  # empty cells stay empty: no "0" to read past
            dark = np.log(conf[i, j]) > 0.6 * np.log(vmax)
            ax.text(
                j,
                i,
                str(int(conf[i, j])),
                ha="center",
                va="center",
                fontsize=fs,
                color="white" if dark else ("tab:red" if i != j else "black"),
            )
    total, wrong = int(conf.sum()), int(conf.sum() - np.trace(conf))
    if title is None:
        acc = 100.0 * (total - wrong) / total if total else float("nan")
        count = f"{wrong:,} of {total:,}".replace(",", " ")  # the paper's "34 of 28 800"
        title = f"Touch: {acc:.2f} % correct, {count} frames misclassified"
    ax.set_title(title, fontsize=9)
    return _finish(fig, show)


def cell_font_size(ax: Any, n: int, digits: int) -> float:
    """The font size (points) of numbers in the cells of an ``n`` × ``n`` grid drawn on ``ax``:
    as large as the cell allows (a number of ``digits`` digits fits its width with a margin),
    at most 10 pt and at least 4 pt. The cell size is measured after the figure's layout."""
    fig = ax.figure
    fig.draw_without_rendering()  # constrained layout places the axes
    box = ax.get_window_extent()
    cell_pt = min(box.width, box.height) / n * 72.0 / fig.dpi
    # a digit is about 0.6 em wide; keep 15 % of the cell free around the number
    return float(np.clip(min(0.45 * cell_pt, 0.85 * cell_pt / (0.6 * max(digits, 1))), 4.0, 10.0))


def _equal_3d(ax: Any, pts: np.ndarray, margin: float = 5.0) -> None:
    """Equal scale on the three axes around ``pts`` (n, 3)."""
    lo, hi = pts.min(0), pts.max(0)
    centre, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2 + margin, 1.0)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))


def plot_tracking_examples(
    pred: Any,
    true: Any,
    *,
    init: Any = None,
    titles: Sequence[str] | None = None,
    axes: Sequence[Any] | None = None,
    show: bool = False,
) -> Figure:
    """Fig. 9: tracking examples, estimated markers (red) against ground truth (blue) in 3D.

    Parameters
    ----------
    pred, true : (K, M, 3) array
        Estimated and true coordinates of the M markers for K examples (6 in the paper), mm.
    init : (K, M, 3) array, optional
        Coordinates at the trajectory's first frame (the prior), drawn as grey ghosts.
    titles : list of K str, optional
        Prefixes of the panel titles (e.g. the trial and frame); each title ends with the example's
        average distance (Eq. 3 over its M markers).
    axes : sequence of K 3D Axes, optional
        Where to draw (``projection="3d"``); a new figure with a 2 × ceil(K/2) grid otherwise.
    """
    p = check_array("pred", pred, (None, None, 3))
    t = check_array("true", true, p.shape)
    k = p.shape[0]
    if k == 0:
        raise EctskinError("plot_tracking_examples: no examples to draw")
    ini = None if init is None else check_array("init", init, p.shape)
    if titles is not None and len(titles) != k:
        raise EctskinError(f"titles has {len(titles)} entries for {k} examples")
    if axes is None:
        ncol = int(np.ceil(k / 2)) if k > 3 else k
        nrow = int(np.ceil(k / ncol))
        fig = _new_figure(show, figsize=(3.4 * ncol, 3.6 * nrow), layout="constrained")
        axs = [fig.add_subplot(nrow, ncol, i + 1, projection="3d") for i in range(k)]
    else:
        axs = list(axes)
        if len(axs) != k:
            raise EctskinError(f"axes has {len(axs)} entries for {k} examples")
        fig = axs[0].figure
    for i, ax in enumerate(axs):
        ad = float(np.linalg.norm(p[i] - t[i], axis=-1).mean())  # Eq. 3 over this example
        if ini is not None:
            ax.plot(*ini[i].T, "o--", color="0.7", ms=3, lw=0.8, label="initial")
        ax.plot(*t[i].T, "o-", color=COLOR_TRUE, ms=4, lw=1, label="true")
        ax.plot(*p[i].T, "^-", color=COLOR_EST, ms=4, lw=1, label="estimated")
        pts = np.concatenate([p[i], t[i]] + ([ini[i]] if ini is not None else []))
        _equal_3d(ax, pts)
        ax.set_xlabel("x (mm)", fontsize=7, labelpad=-6)
        ax.set_ylabel("y (mm)", fontsize=7, labelpad=-6)
        ax.set_zlabel("z (mm)", fontsize=7, labelpad=-6)
        ax.tick_params(labelsize=6, pad=-2)
        head = f"{titles[i]}\n" if titles is not None else ""
        ax.set_title(f"{head}AD = {ad:.3f} mm", fontsize=8)
        if i == 0:
            ax.legend(fontsize=6, loc="upper left")
    return _finish(fig, show)


def plot_marker_trajectory(
    time_s: Any,
    pred: Any,
    true: Any,
    *,
    marker_name: str = "marker",
    title: str | None = None,
    axes: Sequence[Any] | None = None,
    show: bool = False,
) -> Figure:
    """Fig. 10: one marker's trajectory, x, y and z against time, estimated (red) vs true (blue).

    Parameters
    ----------
    time_s : (T,) array
        Time of each frame, s.
    pred, true : (T, 3) array
        Estimated and true coordinates of the marker, mm.
    axes : sequence of 3 Axes, optional
        One per coordinate; a new figure with three stacked panels otherwise.
    """
    tt = check_array("time_s", time_s, (None,))
    p = check_array("pred", pred, (tt.shape[0], 3))
    t = check_array("true", true, (tt.shape[0], 3))
    if axes is None:
        fig = _new_figure(show, figsize=(7.0, 5.5), layout="constrained")
        axs = fig.subplots(3, 1, sharex=True)
    else:
        axs = list(axes)
        if len(axs) != 3:
            raise EctskinError(f"axes must hold 3 Axes (x, y, z), got {len(axs)}")
        fig = axs[0].figure
    for c, (ax, name) in enumerate(zip(axs, "xyz")):
        ax.plot(tt, t[:, c], color=COLOR_TRUE, lw=1.2, label="true")
        ax.plot(tt, p[:, c], color=COLOR_EST, lw=1.0, ls="--", label="estimated")
        ax.set_ylabel(f"{name} (mm)")
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("time (s)")
    axs[0].legend(fontsize=8, loc="best")
    ad = float(np.linalg.norm(p - t, axis=-1).mean())
    axs[0].set_title(
        title or f"{marker_name}: AD = {ad:.3f} mm over {tt[-1] - tt[0]:.1f} s", fontsize=9
    )
    return _finish(fig, show)


def plot_learning_curves(
    history: Mapping[str, Sequence[float]],
    *,
    title: str | None = None,
    axes: Any = None,
    show: bool = False,
) -> Figure:
    """Training and validation loss per epoch (from a run's ``metrics.csv``).

    ``history`` maps column names to per-epoch values; uses ``epoch``, ``train_loss`` and
    ``val_loss`` (log scale), and marks the epoch with the lowest validation loss.
    """
    for key in ("epoch", "train_loss", "val_loss"):
        if key not in history:
            raise EctskinError(f"history lacks column {key!r}; has {sorted(history)}")
    ep = np.asarray(history["epoch"], dtype=float)
    tr = np.asarray(history["train_loss"], dtype=float)
    va = np.asarray(history["val_loss"], dtype=float)
    if axes is None:
        fig = _new_figure(show, figsize=(5.0, 3.2), layout="constrained")
        ax = fig.add_subplot()
    else:
        ax, fig = axes, axes.figure
    ax.plot(ep, tr, label="train")
    ax.plot(ep, va, label="validation")
    if len(va) and np.isfinite(va).any():
        b = int(np.nanargmin(va))
        ax.plot(ep[b], va[b], "k*", ms=8, label=f"best (epoch {int(ep[b])})")
    if np.all(tr[np.isfinite(tr)] > 0) and np.all(va[np.isfinite(va)] > 0):
        ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    return _finish(fig, show)
