"""The design report: ``design.md`` and ``design.html`` with a table and maps per layout, and
the figures (the localisation-error map per face with the wires drawn on it; the bound maps of
the information score; the trade-off front of a search). Figures are returned by the plot
functions and saved by the writers.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.ticker import MaxNLocator

from ectskin._check import check_option
from ectskin._files import save_figure_atomic, write_text_atomic
from ectskin.layout import SensorLayout
from ectskin.viz.contact import plot_error_maps
from ectskin.viz.learning import _finish, _new_figure

ROWS = (
    ("electrodes", "n_electrodes", "{:d}"),
    ("pairs", "n_pairs", "{:d}"),
    ("mean localisation error (mm)", "loc_mm_mean", "{:.1f}"),
    ("median localisation error (mm)", "loc_mm_median", "{:.1f}"),
    ("face accuracy", "face_accuracy", "{:.3f}"),
    ("region accuracy (touch model)", "region_accuracy", "{:.3f}"),
    ("force MAE (N)", "force_mae_n", "{:.3f}"),
    ("tracking error AD (mm)", "track_ad_mm", "{:.2f}"),
    ("lowest pair SNR (dB)", ("sensor", "snr_db_min"), "{:.1f}"),
    ("median touch sensitivity / noise", ("sensor", "sensitivity_snr_median"), "{:.1f}"),
    ("sensitivity matrix condition number", ("sensor", "condition_number"), "{:.3g}"),
    ("effective rank (entropy)", ("sensor", "effective_rank"), "{:.1f}"),
    ("rank above 1 % of sigma_max", ("sensor", "rank_1pct"), "{:d}"),
    ("scoring time (s)", ("seconds", "total"), "{:.0f}"),
)
#: the information score's rows (:mod:`ectskin.design.information`)
INFO_ROWS = (
    ("electrodes", "n_electrodes", "{:d}"),
    ("total wire length (mm)", "wire_length_mm", "{:.0f}"),
    ("mean position bound (mm)", "bound_mm_mean", "{:.3g}"),
    ("worst-case (p95) position bound (mm)", "bound_mm_p95", "{:.3g}"),
    ("share of the skin with force bound < 0.1 N", "force_observable_share", "{:.2f}"),
    ("mean position error of a fit with one fingertip (mm)", "fit_error_mm_mean", "{:.3g}"),
    ("worst-case (p95) error of that fit (mm)", "fit_error_mm_p95", "{:.3g}"),
    ("ambiguity: least readout distance (noise units)", "ambiguity_sigma", "{:.3g}"),
    ("information score time (s)", "information_seconds", "{:.0f}"),
    ("information score CPU time (s)", "information_cpu_seconds", "{:.0f}"),
)
#: what a bound search minimises, in this order
BOUND_FRONT_KEYS = ("bound_mm_p95", "n_electrodes", "wire_length_mm")
#: what a fit-error search minimises, in this order
FIT_FRONT_KEYS = ("fit_error_mm_p95", "n_electrodes", "wire_length_mm")
#: what a search on the fit error's median minimises, in this order
FIT_MEDIAN_FRONT_KEYS = ("fit_error_mm_median", "n_electrodes", "wire_length_mm")
#: the y axis of the information fronts, per worst-case key
FRONT_LABELS = {"bound_mm_p95": "worst-case (p95) position bound (mm)",
                "fit_error_mm_p95": "worst-case (p95) fit error, one fingertip (mm)",
                "fit_error_mm_median": "median fit error, one fingertip (mm)"}


def _value(entry: Mapping[str, Any], key) -> Any:
    if isinstance(key, tuple):
        inner = entry.get(key[0])
        return inner.get(key[1]) if isinstance(inner, Mapping) else None
    return entry.get(key)


def _fmt(value: Any, spec: str) -> str:
    if value is None:
        return "n/a"
    try:
        return spec.format(value)
    except (TypeError, ValueError):
        return str(value)


def plot_layout_errors(score: Mapping[str, Any], *, show: bool = False):
    """The localisation-error map per face of one score, the wires drawn over it (white)."""
    layout = SensorLayout.from_dict(score["layout"])
    maps = score["loc_map"]
    extent = {s.surface: (s.u_mm, s.v_mm) for s in layout.skins}
    fig = plot_error_maps(maps, {f: extent[f] for f in maps}, show=show)
    for ax, face in zip(fig.axes, maps):
        for e in layout.electrodes:
            if layout.skin(e.skin).surface != face:
                continue
            ax.plot(*e.polyline_mm.T, color="w", lw=1.6)
            ax.plot(*e.polyline_mm.T, color="k", lw=0.6)
    fig.suptitle(f"{score['name']}: {score['n_electrodes']} electrodes")
    return fig


def plot_front(points: Sequence[Mapping[str, Any]], paper: Mapping[str, Any] | None, *, show=False):
    """The trade-off of a search: mean localisation error against electrode count per scored
    layout (grey), the Pareto-optimal ones (red, joined), the paper's layout (black star)."""
    fig = _new_figure(show, figsize=(5.5, 4.0), layout="constrained")
    ax = fig.subplots()
    n = np.array([p["n_electrodes"] for p in points], dtype=float)
    e = np.array([p["loc_mm_mean"] for p in points], dtype=float)
    ax.scatter(n, e, color="0.6", label="proposed layouts")
    front = pareto_front(points)
    if front:
        fn = [p["n_electrodes"] for p in front]
        fe = [p["loc_mm_mean"] for p in front]
        ax.plot(fn, fe, "o-", color="tab:red", label="trade-off front")
        for p in front:
            ax.annotate(
                p["name"],
                (p["n_electrodes"], p["loc_mm_mean"]),
                fontsize=7,
                xytext=(3, 3),
                textcoords="offset points",
            )
    if paper is not None and paper.get("loc_mm_mean") is not None:
        ax.plot([paper["n_electrodes"]], [paper["loc_mm_mean"]], "k*", ms=12, label="paper")
    ax.set_xlabel("electrodes")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("mean localisation error (mm)")
    ax.legend(fontsize=8)
    return _finish(fig, show)


def pareto_front(
    points: Sequence[Mapping[str, Any]], keys: Sequence[str] = ("n_electrodes", "loc_mm_mean")
) -> list[Mapping[str, Any]]:
    """The points not dominated in ``keys`` (all minimised; a point with a None or NaN value is
    left out, inf counts as the worst), sorted by ``keys`` (ties in all: the first kept)."""
    def vals(p):
        return tuple(float(p[k]) for k in keys)

    ok = [
        p for p in points
        if all(p.get(k) is not None and not np.isnan(float(p[k])) for k in keys)
    ]
    front: list[Mapping[str, Any]] = []
    for p in ok:
        vp = vals(p)
        dominated = any(
            all(a <= b for a, b in zip(vals(q), vp)) and vals(q) != vp for q in ok
        )
        if not dominated and not any(vals(f) == vp for f in front):
            front.append(p)
    return sorted(front, key=vals)


def plot_bound_front(
    points: Sequence[Mapping[str, Any]], paper: Mapping[str, Any] | None, *, show=False,
    key: str = "bound_mm_p95",
):
    """The trade-off of a bound search: the worst-case position bound (``key``: or the fit's
    worst-case error ``fit_error_mm_p95``, or its median ``fit_error_mm_median``; log scale)
    against the electrode count per scored layout, coloured by total wire length; the
    Pareto-optimal ones in (``key``, electrodes, wire length) ringed in red and named; the
    paper's layout a black star. Layouts with an unresolved worst case (inf or None) are
    triangles along the top edge."""
    import matplotlib.pyplot as plt

    check_option("key", key, tuple(FRONT_LABELS))
    fig = _new_figure(show, figsize=(6.0, 4.2), layout="constrained")
    ax = fig.subplots()
    # the plot reads "bound_mm_p95": the key's values under that name
    points = [{**p, "bound_mm_p95": np.inf if p.get(key) is None else p[key]} for p in points]
    if paper is not None:
        paper = {**paper, "bound_mm_p95": paper.get(key)}
    ok = [p for p in points if np.isfinite(p["bound_mm_p95"])]
    unresolved = [p for p in points if not np.isfinite(p["bound_mm_p95"])]
    every = points + ([paper] if paper is not None and paper.get("wire_length_mm") else [])
    lengths = [p["wire_length_mm"] for p in every]
    norm = plt.Normalize(min(lengths), max(lengths)) if lengths else None
    if ok:
        sc = ax.scatter(
            [p["n_electrodes"] for p in ok], [p["bound_mm_p95"] for p in ok],
            c=[p["wire_length_mm"] for p in ok], cmap="viridis", norm=norm, s=30,
            label="proposed layouts",
        )
        fig.colorbar(sc, ax=ax, label="total wire length (mm)")
    finite = [p["bound_mm_p95"] for p in ok] + (
        [paper["bound_mm_p95"]] if paper is not None and paper.get("bound_mm_p95") else []
    )
    top = 2.0 * max(finite) if finite else 1.0  # where an unresolved worst case is drawn
    if unresolved:
        ax.scatter(
            [p["n_electrodes"] for p in unresolved], [top] * len(unresolved), marker="^",
            c=[p["wire_length_mm"] for p in unresolved], cmap="viridis", norm=norm, s=40,
            edgecolors="0.3", label="worst case unresolved (drawn at the top)",
        )
    front = pareto_front(points, BOUND_FRONT_KEYS)
    if front:
        ys = [p["bound_mm_p95"] if np.isfinite(p["bound_mm_p95"]) else top for p in front]
        ax.scatter(
            [p["n_electrodes"] for p in front], ys,
            s=110, facecolors="none", edgecolors="tab:red", label="trade-off front",
        )
        for p, y in zip(front, ys):
            ax.annotate(p["name"], (p["n_electrodes"], y), fontsize=7,
                        xytext=(4, 3), textcoords="offset points")
    if paper is not None and paper.get("bound_mm_p95") is not None:
        ax.scatter([paper["n_electrodes"]], [paper["bound_mm_p95"]], marker="*", s=180,
                   c=[paper["wire_length_mm"]], cmap="viridis", norm=norm, edgecolors="k",
                   label="paper")
    ax.set_yscale("log")
    ax.set_xlabel("electrodes")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(FRONT_LABELS[key])
    # below the axes: inside, it can hide the paper's star
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    return _finish(fig, show)


def plot_layout_bounds(score: Mapping[str, Any], *, show: bool = False):
    """The information score's bound maps of one layout (position and force over each face, per
    inflation state; every nuisance estimated), wires drawn
    (:func:`~ectskin.viz.bound.plot_bound_maps`)."""
    from ectskin.viz.bound import plot_bound_maps

    maps = score["maps"]
    case = maps["cases"][-1]
    fig = plot_bound_maps(maps, cases=(case,), show=show)
    fig.suptitle(f"{score['name']}: Cramér–Rao bounds, {case} nuisances estimated")
    return fig


def _about(design: Mapping[str, Any]) -> str:
    """One paragraph on how the layouts were scored."""
    s = design["settings"]
    parts = []
    if "protocol" in s:
        proto = s["protocol"]
        parts.append(
            f"Trained score: protocol of {len(proto['levels_ml'])} levels {proto['levels_ml']} ml "
            f"per chamber, {proto['touch_trials']} touch trials per state of "
            f"{proto['duration_s']:g} s, {proto['touch_dwells']} dwells, placement "
            f"{proto['touch_placement']!r}, "
            + (
                "read from the states' response fields (spacing "
                f"{s['field_grid']['spacing_mm']} mm), "
                if s.get("response") == "field"
                else "solved per dwell, "
            )
            + f"seed {proto['seed']}; quick training, epochs "
            f"{s['epochs']}. Errors are comparable between layouts of this report (the same "
            f"touches), not with the paper's protocol."
        )
    info = s if "states_ml" in s else design.get("information_settings")
    if info:
        parts.append(
            f"Information score: Cramér–Rao bounds of (u, v, F) at {info['force_n']:g} N on a "
            f"{info['spacing_mm']:g} mm grid of both faces, at inflation states "
            f"{info['states_ml']} ml, {info['mesh']} mesh, nuisances {info['nuisances']} "
            f"estimated (priors {info['prior_sd']}); ambiguity between points more than "
            f"{info['separation_mm']:g} mm apart."
        )
    parts.append(
        f"Engine: {design['engine']['address']} with {design['engine']['n_workers']} worker(s); "
        f"{design['sweep_seconds']:.0f} s."
    )
    return " ".join(parts)


def write_report(
    out: str | Path,
    design: Mapping[str, Any],
    scores: Mapping[str, Mapping[str, Any]],
    *,
    extra_figures: Sequence[tuple[str, str]] = (),
    intro: Sequence[str] = (),
) -> None:
    """Write the maps of every layout (``figures/<name>_errors.png`` for a trained score,
    ``figures/<name>_bound.png`` for an information score) and the report ``design.md`` /
    ``design.html`` in ``out``. ``extra_figures`` are (caption, relative path) shown first (the
    search's front). Rows without a value for any layout are left out."""
    out = Path(out)
    figures: list[list[tuple[str, str]]] = []
    for entry in design["layouts"]:
        name = entry["name"]
        mine = []
        for kind, key, plot, caption in (
            ("errors", "loc_map", plot_layout_errors, "localisation error per face"),
            ("bound", "maps", plot_layout_bounds, "Cramér–Rao bound maps"),
        ):
            if scores[name].get(key):
                fig = plot({**scores[name], "name": name})
                rel = f"figures/{name}_{kind}.png"
                save_figure_atomic(fig, out / rel)
                _close(fig)
                mine.append((caption, rel))
        figures.append(mine)
    about = _about(design)
    lines_md = ["# Electrode layouts scored in the twin", ""]
    lines_md += list(intro)
    lines_md += [about, ""]
    for cap, rel in extra_figures:
        lines_md += [f"![{cap}]({rel})", ""]
    names = [e["name"] for e in design["layouts"]]
    header = ["", *names]
    present = []
    for row in (*ROWS, *INFO_ROWS[1:]):
        if any(_value(e, row[1]) is not None for e in design["layouts"]):
            present.append(row)
    rows = [
        [label, *(_fmt(_value(e, key), spec) for e in design["layouts"])]
        for label, key, spec in present
    ]
    lines_md += ["## Summary", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines_md += ["| " + " | ".join(r) + " |" for r in rows]
    lines_md.append("")
    verdicts, claims = _verdicts(design["layouts"])
    agreement = rank_agreement(design["layouts"])
    goal = goal_line(design["layouts"])
    notes = [*claims, *([goal] if goal else []), *([agreement] if agreement else [])]
    if verdicts:
        head = ["layout", "metric", "difference (layout − paper)", "95 % CI", "seeds", "verdict"]
        lines_md += [
            "## Against the paper's layout (paired over seeds, the same test touches)", "",
            *notes, "",
            "| " + " | ".join(head) + " |", "|" + "---|" * len(head),
            *("| " + " | ".join(r) + " |" for r in verdicts), "",
        ]
    elif agreement:
        lines_md += [agreement, ""]
    html_parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>ectskin design</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "td,th{border:1px solid #ccc;padding:3px 6px}table{border-collapse:collapse}</style>"
        "</head><body>",
        "<h1>Electrode layouts scored in the twin</h1>",
        *(f"<p>{html.escape(t)}</p>" for t in intro if t),
        f"<p>{html.escape(about)}</p>",
        *(
            f"<figure><img src='{html.escape(rel)}' width='520'><figcaption>{html.escape(cap)}"
            f"</figcaption></figure>"
            for cap, rel in extra_figures
        ),
        "<h2>Summary</h2><table><tr>"
        + "".join(f"<th>{html.escape(h)}</th>" for h in header)
        + "</tr>",
        *("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows),
        "</table>",
        *(f"<p>{html.escape(t)}</p>" for t in notes),
    ]
    if verdicts:
        html_parts.append("<h2>Against the paper's layout (paired over seeds)</h2><table>")
        html_parts += [
            "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in verdicts
        ]
        html_parts.append("</table>")
    for entry, mine in zip(design["layouts"], figures):
        name = entry["name"]
        per_face = entry.get("loc_mm_per_face", {})
        table = [(label, _fmt(_value(entry, key), spec)) for label, key, spec in present]
        table += [
            (f"mean localisation error, {f} face (mm)", _fmt(v, "{:.1f}"))
            for f, v in per_face.items()
        ]
        lines_md += [
            f"## {name}",
            "",
            f"Layout file: `{entry['folder']}/layout.json`",
            "",
            "| metric | value |",
            "|---|---|",
        ]
        lines_md += [f"| {a} | {b} |" for a, b in table]
        html_parts.append(f"<h2>{html.escape(name)}</h2><table>")
        html_parts += [
            f"<tr><td>{html.escape(a)}</td><td>{html.escape(b)}</td></tr>" for a, b in table
        ]
        html_parts.append("</table>")
        for caption, rel in mine:
            lines_md += ["", f"![{name}: {caption}]({rel})"]
            html_parts.append(f"<img src='{html.escape(rel)}' width='520'>")
        lines_md.append("")
    html_parts.append("</body></html>")
    write_text_atomic(out / "design.md", "\n".join(lines_md) + "\n")
    write_text_atomic(out / "design.html", "\n".join(html_parts) + "\n")


def _verdicts(layouts: Sequence[Mapping[str, Any]]) -> tuple[list[list[str]], list[str]]:
    """Rows of the paired comparisons (``vs_paper``) and the claims they allow: a layout is
    "better than the paper" in a metric only where the 95 % interval excludes zero."""
    rows, claims = [], []
    for e in layouts:
        for metric, c in e.get("vs_paper", {}).items():
            d = c["difference"]
            lo, hi = d["ci"]
            ci = f"{_fmt(lo, '{:+.3g}')} … {_fmt(hi, '{:+.3g}')}"
            rows.append([e["name"], metric, f"{d['mean']:+.3g}", ci, str(d["n"]), c["verdict"]])
            if c["verdict"] == "better":
                claims.append(
                    f"{e['name']} is better than the paper's layout in {metric}: "
                    f"{d['mean']:+.3g} (95 % CI {ci}, {d['n']} seeds)."
                )
    return rows, claims


#: the information scores whose ranking is set beside the trained score's, and their names
AGREEMENT_SCORES = (("bound_mm_p95", "worst-case bound"),
                    ("fit_error_mm_p95", "worst-case error of a fit with one fingertip"),
                    ("fit_error_mm_median", "median error of a fit with one fingertip"))


def rank_agreement(layouts: Sequence[Mapping[str, Any]]) -> str | None:
    """One line per information score (:data:`AGREEMENT_SCORES`): does it rank the layouts as
    the trained score (mean localisation error) does (:func:`~ectskin.design.stats.rank_agreement`;
    None with fewer than 3 layouts with both)?"""
    from ectskin.design.stats import rank_agreement as agreement

    lines = []
    for key, name in AGREEMENT_SCORES:
        r = agreement(layouts, key=key)
        if r is None:
            continue
        if r["rho"] is None:
            lines.append(
                f"The information score ({name}) and the trained score cannot be compared by "
                f"rank: one of them ties all {r['n']} layouts."
            )
            continue
        word = "agree on" if r["agree"] else "do not agree on"
        seeds = r.get("seeds")
        said = ""
        if seeds is not None and seeds["rho_ci"] is not None:
            lo, hi = seeds["rho_ci"]
            said = (f"; over the {seeds['n_seeds']} seeds resampled, "
                    f"{100 * seeds['level']:g} % of rho in [{lo:.2f}, {hi:.2f}]")
            if seeds["seed_to_seed_rho"] is not None:
                said += (f", and the trained rankings of two seeds agree at rho = "
                         f"{seeds['seed_to_seed_rho']:.2f} on average")
        lines.append(
            f"The information score ({name}) and the trained score (mean localisation error) "
            f"{word} the ranking: Spearman rho = {r['rho']:.2f} over {r['n']} layouts "
            f"(agreement: rho >= {r['threshold']:g}){said}."
        )
    return " ".join(lines) or None


def goal_line(layouts: Sequence[Mapping[str, Any]]) -> str | None:
    """One line on the goal (:func:`~ectskin.design.stats.goal_layouts`): which layouts with at
    most 8 electrodes have at most half the paper's worst-case bound, and which of them are
    shown better than the paper in mean localisation error; None without the paper's bound or
    a paired comparison."""
    from ectskin.design.stats import goal_layouts

    if not any("vs_paper" in e for e in layouts):
        return None
    g = goal_layouts(layouts)
    if g["paper_bound_mm_p95"] is None:
        return None
    half = ", ".join(g["half_bound"]) or "none"
    met = ", ".join(g["met"]) or "none"
    return (
        f"At most {g['max_electrodes']} electrodes and a worst-case bound at most "
        f"{g['bound_share']:g} x the paper's ({g['paper_bound_mm_p95']:.3g} mm): {half}; of these, "
        f"a lower mean localisation error than the paper's with a 95 % interval that excludes "
        f"zero: {met}."
    )


def _close(fig) -> None:
    import matplotlib.pyplot as plt

    plt.close(fig)
