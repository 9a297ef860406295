"""The design report: ``design.md`` and ``design.html`` with a table and heat maps per layout,
and the figures (localisation-error map per face with the wires drawn on it; the trade-off
front of a search). Figures are returned by the plot functions and saved by the writers.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.ticker import MaxNLocator

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


def _value(entry: Mapping[str, Any], key) -> Any:
    if isinstance(key, tuple):
        return entry.get(key[0], {}).get(key[1])
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


def pareto_front(points: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """The points not dominated in (n_electrodes, loc_mm_mean), both minimised, sorted by
    electrode count (ties in both: the first kept)."""
    ok = [p for p in points if p.get("loc_mm_mean") is not None and np.isfinite(p["loc_mm_mean"])]
    front = []
    for p in ok:
        dominated = any(
            q["n_electrodes"] <= p["n_electrodes"]
            and q["loc_mm_mean"] <= p["loc_mm_mean"]
            and (q["n_electrodes"], q["loc_mm_mean"]) != (p["n_electrodes"], p["loc_mm_mean"])
            for q in ok
        )
        if not dominated and not any(
            (f["n_electrodes"], f["loc_mm_mean"]) == (p["n_electrodes"], p["loc_mm_mean"])
            for f in front
        ):
            front.append(p)
    return sorted(front, key=lambda p: (p["n_electrodes"], p["loc_mm_mean"]))


def write_report(
    out: str | Path,
    design: Mapping[str, Any],
    scores: Mapping[str, Mapping[str, Any]],
    *,
    extra_figures: Sequence[tuple[str, str]] = (),
    intro: Sequence[str] = (),
) -> None:
    """Write the heat map of every layout to ``figures/<name>_errors.png`` and the report
    ``design.md`` / ``design.html`` in ``out``. ``extra_figures`` are (caption, relative path)
    shown first (the search's front)."""
    out = Path(out)
    figures = []
    for entry in design["layouts"]:
        name = entry["name"]
        if scores[name].get("loc_map"):
            fig = plot_layout_errors({**scores[name], "name": name})
            rel = f"figures/{name}_errors.png"
            save_figure_atomic(fig, out / rel)
            _close(fig)
            figures.append(rel)
        else:
            figures.append(None)
    s = design["settings"]
    proto = s["protocol"]
    lines_md = ["# Electrode layouts scored in the twin", ""]
    lines_md += list(intro)
    about = (
        f"Protocol: {len(proto['levels_ml'])} levels {proto['levels_ml']} ml per chamber, "
        f"{proto['touch_trials']} touch trials per state of {proto['duration_s']:g} s, "
        f"{proto['touch_dwells']} dwells, placement {proto['touch_placement']!r}, seed "
        f"{proto['seed']}; quick training, epochs {s['epochs']}. Engine: "
        f"{design['engine']['address']} with {design['engine']['n_workers']} worker(s); sweep "
        f"{design['sweep_seconds']:.0f} s. Errors are comparable between layouts of this report "
        f"(the same touches), not with the paper's protocol."
    )
    lines_md += [about, ""]
    for cap, rel in extra_figures:
        lines_md += [f"![{cap}]({rel})", ""]
    names = [e["name"] for e in design["layouts"]]
    header = ["", *names]
    rows = [
        [label, *(_fmt(_value(e, key), spec) for e in design["layouts"])]
        for label, key, spec in ROWS
    ]
    lines_md += ["## Summary", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines_md += ["| " + " | ".join(r) + " |" for r in rows]
    lines_md.append("")
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
    ]
    for entry, rel in zip(design["layouts"], figures):
        name = entry["name"]
        per_face = entry.get("loc_mm_per_face", {})
        table = [(label, _fmt(_value(entry, key), spec)) for label, key, spec in ROWS]
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
        if rel:
            lines_md += ["", f"![{name}: localisation error per face]({rel})"]
            html_parts.append(f"<img src='{html.escape(rel)}' width='520'>")
        lines_md.append("")
    html_parts.append("</body></html>")
    write_text_atomic(out / "design.md", "\n".join(lines_md) + "\n")
    write_text_atomic(out / "design.html", "\n".join(html_parts) + "\n")


def _close(fig) -> None:
    import matplotlib.pyplot as plt

    plt.close(fig)
