"""Figures of the Cramér–Rao bound maps (:func:`ectskin.twin.bound.bound_maps`,
:func:`ectskin.twin.bound_field.field_bound_maps`), and a model's error beside them.

Like the other plot functions: ``axes=None, show=False``, the Figure is returned, nothing is saved.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from ectskin._check import EctskinError
from ectskin.viz.learning import _finish, _new_figure

#: what the third parameter is called in each mode of the maps, and its unit
_THIRD = {"contact": ("force_n", "force bound (N)"), "hover": ("height_mm", "height bound (mm)")}


def _grid(values: Any) -> np.ma.MaskedArray:
    """A map from JSON (None: unresolved) or arrays (inf: unresolved), masked where unresolved."""
    a = np.array([[np.nan if x is None else x for x in row] for row in values], dtype=float)
    return np.ma.masked_invalid(a)


def _norm(grids: Sequence[np.ma.MaskedArray]) -> LogNorm:
    """One log scale over the positive finite values of ``grids``."""
    vals = np.concatenate([g.compressed() for g in grids]) if grids else np.zeros(0)
    vals = vals[vals > 0]
    if vals.size == 0:
        return LogNorm(1e-3, 1.0)
    lo, hi = float(vals.min()), float(vals.max())
    return LogNorm(lo, hi if hi > lo else lo * 10)


def plot_bound_maps(
    maps: Mapping[str, Any],
    *,
    mode: str = "contact",
    cases: Sequence[str] = ("none", "all"),
    axes: Any = None,
    show: bool = False,
) -> Figure:
    """The position and force (or height) bounds over each face, per state and case.

    Rows: each state of ``maps`` × each of ``cases``; columns: the position on each face, then
    the force (or height) on each face. Log colour scales, one per quantity, shared by all panels; grey: unresolved; the
    wires (``maps["wires"]``) in black; on force panels a dashed contour at the force threshold.
    ``axes``: an (n_rows, n_cols) array of Axes to draw into, or None for a new figure.
    """
    if mode not in maps.get("modes", ()):
        raise EctskinError(f"plot_bound_maps: mode {mode!r} is not in the maps ({maps.get('modes')})")
    unknown = [c for c in cases if c not in maps["cases"]]
    if unknown:
        raise EctskinError(f"plot_bound_maps: cases {unknown} are not in the maps ({maps['cases']})")
    third, third_label = _THIRD[mode]
    faces = list(maps["settings"]["faces"])
    rows = [(s, c) for s in maps["states"] for c in cases]
    n_rows, n_cols = len(rows), 2 * len(faces)
    if axes is None:
        fig = _new_figure(show, figsize=(2.3 * n_cols + 1.5, 3.6 * n_rows + 0.6), layout="constrained")
        ax = np.asarray(fig.subplots(n_rows, n_cols, squeeze=False))
    else:
        ax = np.asarray(axes, dtype=object).reshape(n_rows, n_cols)
        fig = ax.flat[0].figure
    grids = {
        (r, f, q): _grid(state["faces"][f][mode][case][q])
        for r, (state, case) in enumerate(rows)
        for f in faces
        for q in ("position_mm", third)
    }
    norms = {q: _norm([g for k, g in grids.items() if k[2] == q]) for q in ("position_mm", third)}
    threshold = maps["settings"].get("force_threshold_n")
    images: dict[str, Any] = {}
    for r, (state, case) in enumerate(rows):
        for j, face in enumerate(faces):
            skin = maps["skins"][face]
            for k, q in enumerate(("position_mm", third)):
                a = ax[r, k * len(faces) + j]
                g = grids[(r, face, q)]
                (u0, u1), (v0, v1) = skin["u_mm"], skin["v_mm"]
                ue = np.linspace(u0, u1, g.shape[1] + 1)
                ve = np.linspace(v0, v1, g.shape[0] + 1)
                cmap = "viridis" if q == "position_mm" else "magma"
                images[q] = a.pcolormesh(ue, ve, g, norm=norms[q], cmap=cmap)
                a.set_facecolor("0.75")  # unresolved cells are masked: the grey shows through
                for wire in maps["wires"].get(face, []):
                    w = np.asarray(wire, float)
                    a.plot(w[:, 0], w[:, 1], color="k", lw=1.2)
                if (q == "force_n" and threshold and min(g.shape) > 1 and g.count()
                        and g.min() < threshold < g.max()):  # contour needs 2 x 2 cells
                    uc, vc = 0.5 * (ue[1:] + ue[:-1]), 0.5 * (ve[1:] + ve[:-1])
                    a.contour(uc, vc, g, levels=[threshold], colors="w", linestyles="--")
                a.set_aspect("equal")
                if r == 0:
                    a.set_title(f"{face}: {'position' if k == 0 else third.split('_')[0]}")
                if r == n_rows - 1:
                    a.set_xlabel("u (mm)")
        p = ", ".join(f"{x:g}" for x in state["inflation_ml"])
        ax[r, 0].set_ylabel(f"p = ({p}) ml, {case}\nv (mm)")
    n = len(faces)
    fig.colorbar(images["position_mm"], ax=list(ax[:, :n].flat), label="position bound (mm)",
                 shrink=0.6)
    fig.colorbar(images[third], ax=list(ax[:, n:].flat), label=third_label, shrink=0.6)
    return _finish(fig, show)


def _mean_over_states(maps: Mapping[str, Any], face: str, case: str) -> np.ma.MaskedArray:
    """The position bound of ``case`` on ``face`` averaged over the states (unresolved cells
    left out of the average; masked where no state resolves the cell)."""
    grids = [_grid(s["faces"][face]["contact"][case]["position_mm"]) for s in maps["states"]]
    return np.ma.mean(np.ma.stack(grids), axis=0)


def plot_error_vs_bound(
    error_maps: Mapping[str, Any],
    maps: Mapping[str, Any],
    *,
    case: str = "all",
    axes: Any = None,
    show: bool = False,
) -> Figure:
    """A contact model's localisation error beside the physical limit, per face.

    Row per face of ``maps``: the model's mean error per cell (``error_maps[face]``: ``u_edges``,
    ``v_edges``, ``mean_mm`` (nv, nu), from the contact metrics' ``map``) and the position bound
    of ``case`` averaged over the maps' states. One log colour scale for both, so the gap between
    them reads as a colour step; wires in black; grey: no test frame / unresolved.
    ``axes``: an (n_faces, 2) array of Axes, or None for a new figure.
    """
    if case not in maps.get("cases", ()):
        raise EctskinError(f"plot_error_vs_bound: case {case!r} is not in the maps ({maps.get('cases')})")
    faces = [f for f in maps["settings"]["faces"] if f in error_maps]
    if not faces:
        raise EctskinError(
            f"plot_error_vs_bound: the error maps cover {sorted(error_maps)}, the bound maps "
            f"{list(maps['settings']['faces'])}: no face in common"
        )
    if axes is None:
        fig = _new_figure(show, figsize=(6.0, 5.2 * len(faces) + 0.6), layout="constrained")
        ax = np.asarray(fig.subplots(len(faces), 2, squeeze=False))
    else:
        ax = np.asarray(axes, dtype=object).reshape(len(faces), 2)
        fig = ax.flat[0].figure
    err = {f: _grid(error_maps[f]["mean_mm"]) for f in faces}
    bnd = {f: _mean_over_states(maps, f, case) for f in faces}
    norm = _norm(list(err.values()) + list(bnd.values()))
    image: Any = None
    for r, face in enumerate(faces):
        e = error_maps[face]
        (u0, u1), (v0, v1) = maps["skins"][face]["u_mm"], maps["skins"][face]["v_mm"]
        b = bnd[face]
        panels = (
            (np.asarray(e["u_edges"], float), np.asarray(e["v_edges"], float), err[face],
             "model's error"),
            (np.linspace(u0, u1, b.shape[1] + 1), np.linspace(v0, v1, b.shape[0] + 1), b,
             f"bound ({case})"),
        )
        for k, (ue, ve, g, title) in enumerate(panels):
            a = ax[r, k]
            image = a.pcolormesh(ue, ve, g, norm=norm, cmap="viridis")
            a.set_facecolor("0.75")
            for wire in maps["wires"].get(face, []):
                w = np.asarray(wire, float)
                a.plot(w[:, 0], w[:, 1], color="k", lw=1.2)
            a.set_aspect("equal")
            a.set_title(f"{face}: {title}")
            a.set_xlabel("u (mm)")
        ax[r, 0].set_ylabel("v (mm)")
    fig.colorbar(image, ax=list(ax.flat), label="position error / bound (mm)", shrink=0.6)
    return _finish(fig, show)
