"""Render a metrics dict as ``report.md`` and a self-contained ``report.html``.

The report is one list of sections (headings, paragraphs, tables, lists, figures), rendered to
Markdown and to HTML alike, with a table of contents linking its headings. Markdown references
images by relative path; the HTML embeds PNG and SVG figures as base64 so it can be mailed
around as one file (a PDF figure cannot be shown inline: both link it). Both files are written
atomically (:mod:`ectskin._files`).
"""

from __future__ import annotations

import base64
import html
import logging
import re
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin._files import write_text_atomic
from ectskin.report.contact import contact_sections
from ectskin.report.reading import reading_paragraph
from ectskin.report.tables import (
    ROBUST_LABEL,
    ablation_note,
    ablation_rows,
    margin_text,
    results_table,
)
from ectskin.report.wording import DASH, duration, lookup, mm

log = logging.getLogger(__name__)

#: Figures the twin's ``characterize`` step writes (file stem, caption), included when present
#: in the output folder in one of :data:`FIGURE_SUFFIXES`.
CHARACTERIZE_FIGURES = (
    ("characterize/fig3_inflation", "Fig. 3: response to inflation (digital twin)"),
    ("characterize/fig4_touch", "Fig. 4: two-stage touch response (digital twin)"),
)
#: figure files the report shows, and the MIME type of the inline ones (PDF is linked)
FIGURE_SUFFIXES = {".png": "image/png", ".svg": "image/svg+xml", ".pdf": None}
#: the report's names of the machine fields (:func:`ectskin.report.machine.machine_info`)
MACHINE_LABELS = {
    "platform": "operating system",
    "python": "Python",
    "processor": "processor",
    "cpu_count": "CPU cores",
    "ectskin": "ectskin",
    "torch": "torch",
    "torch_threads": "torch CPU threads",
    "gpu": "GPU",
}


def _collect_figures(out_dir: Path, figures: Any) -> list[tuple[str, Path]]:
    """Normalise ``figures`` to [(caption, absolute path)], adding the twin's Fig. 3/4 if present."""
    items: list[tuple[str, Path]] = []
    if isinstance(figures, Mapping):
        pairs = list(figures.items())
    else:
        pairs = [(Path(p).stem, p) for p in (figures or [])]
    for caption, p in pairs:
        path = Path(p)
        if not path.is_absolute():
            path = out_dir / path
        if not path.is_file():
            raise EctskinError(f"report figure {caption!r}: file {path} does not exist")
        items.append((str(caption), path))
    have = {p.resolve() for _, p in items}
    for stem, caption in CHARACTERIZE_FIGURES:
        for suffix in FIGURE_SUFFIXES:
            path = out_dir / f"{stem}{suffix}"
            if path.is_file() and path.resolve() not in have:
                items.append((caption, path))
                break
    return items


def slug(title: str) -> str:
    """The anchor of a heading, as GitHub renders Markdown: "Margin over the baselines" →
    "margin-over-the-baselines"."""
    text = re.sub(r"[^\w\- ]", "", title.strip().lower())
    return text.replace(" ", "-")


def machine_value(key: str, value: Any) -> str:
    """A machine field as the report writes it: lists joined, an empty GPU list as "none"."""
    if isinstance(value, list | tuple):
        if not value:
            return "none (CPU only)" if key == "gpu" else "none"
        return ", ".join(str(v) for v in value)
    return DASH if value is None else str(value)


def _rel(path: Path, out_dir: Path) -> str:
    try:
        return path.resolve().relative_to(out_dir.resolve()).as_posix()
    except ValueError:
        return path.resolve().as_posix()


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """The lines of a Markdown table: ``header``, the rule, one line per row, a ``|`` inside a
    cell escaped (``\\|``) so that it cannot split the cell."""

    def esc(s: str) -> str:
        return str(s).replace("|", "\\|")

    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(esc(c) for c in r) + " |" for r in rows]
    return lines


def _html_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _sections(metrics: Mapping[str, Any], figures: list[tuple[str, Path]]) -> list[tuple[str, Any]]:
    """The report as a list of (kind, payload): ("h2", text), ("p", text), ("table", (hdr, rows)),
    ("list", items), ("figure", (caption, path)); rendered to Markdown and HTML alike."""
    s: list[tuple[str, Any]] = []
    intro = (
        "This report sets the results of this run beside those of the paper (Hu et al., §4) and "
        "beside baselines trained on the same training trials and scored on the same test "
        "trials. A model is only as good as its margin over the strongest of them."
    )
    prof = lookup(metrics, "profile")
    if prof:
        intro += f" Training profile: `{prof}`."
    s.append(("p", intro))
    data = lookup(metrics, "data")
    if isinstance(data, Mapping) and data:
        desc = ", ".join(f"{k}: {v}" for k, v in data.items())
        s.append(("p", f"Data: {desc}."))
    lead = reading_paragraph(metrics)
    if lead:
        s.append(("h2", "Paper recipe on this reading of the experiment"))
        s.append(("p", lead))
    s.append(("h2", "Results"))
    s.append(("table", (("metric", "paper", "this run", "baselines"), results_table(metrics))))
    robust = lookup(metrics, "touch.robust")
    if robust:
        recipe = lookup(robust, "recipe_description")
        text = (
            f'"{ROBUST_LABEL}" is the paper\'s TouchMLP, unchanged, trained with the `robust` '
            "profile instead of the paper's recipe"
            + (f": {recipe}" if recipe else "")
            + ". It is evaluated on the same test trials. On the twin the paper's recipe fits the "
            "training trials exactly and keeps the weights of one of its first epochs (its "
            "validation loss rises from then on): the test trials are other trials."
        )
        extra = lookup(robust, "training.recipe.extra_train") or []
        if any(e.get("file") == "coverage.h5" for e in extra):
            text += (
                " Its training split also holds the twin's coverage trials (coverage.h5: every "
                "region touched at two points in every inflation state, 3 s each, "
                "ectskin.twin.coverage), since the experiment touches each region in about a "
                "third of the states; validation and test are the experiment's trials, and the "
                "baselines beside it are fitted on the same training trials."
            )
        s.append(("p", text))
    margins = margin_text(metrics)
    if margins:
        s.append(("h2", "Margin over the strongest baseline"))
        s.append(("list", margins))
    confusions = lookup(metrics, "touch.confusions") or []
    if confusions:
        rows: list[tuple[str, ...]] = [
            (
                str(c.get("true")),
                str(c.get("pred")),
                str(c.get("count")),
                {True: "yes", False: "no"}.get(c.get("adjacent"), DASH),
            )
            for c in confusions[:10]
        ]
        s.append(("h2", "Largest touch confusions"))
        s.append(("table", (("true class", "predicted", "frames", "adjacent regions"), rows)))
    s.extend(contact_sections(metrics))
    abl = ablation_rows(metrics)
    if abl:
        s.append(("h2", "Tracking ablations"))
        s.append(("table", (("variant", "epochs", "AD (Eq. 3)", "change vs full model"), abl)))
        note = ablation_note(metrics)
        if note:
            s.append(("p", note))
        if len({r[1] for r in abl}) > 1:
            s.append(
                (
                    "p",
                    (
                        "The variants were trained for different numbers of epochs (the quick "
                        "profile shortens the ablations to fit its time budget), which favours "
                        "the variant trained longest; compare them with that in mind."
                    ),
                )
            )
    per_marker = lookup(metrics, "track.per_marker") or {}
    if per_marker:
        rows = [
            (name, mm(lookup(v, "ad_mm_mean"), lookup(v, "ad_mm_std")))
            for name, v in per_marker.items()
        ]
        s.append(("h2", "Tracking per marker"))
        s.append(("table", (("marker", "AD"), rows)))
    timings = lookup(metrics, "timings_s") or {}
    if timings:
        reused = set(lookup(metrics, "reused") or [])
        s.append(("h2", "Timings"))
        if reused:
            rows = [
                (step, duration(sec), "reused (time of the earlier run)" if step in reused else "")
                for step, sec in timings.items()
            ]
            s.append(("table", (("step", "time", "reused"), rows)))
        else:
            rows = [(step, duration(sec)) for step, sec in timings.items()]
            s.append(("table", (("step", "time"), rows)))
    machine = lookup(metrics, "machine") or {}
    if machine:
        s.append(("h2", "Machine"))
        rows = [(MACHINE_LABELS.get(k, k), machine_value(k, v)) for k, v in machine.items()]
        s.append(("table", (("component", "value"), rows)))
    if figures:
        s.append(("h2", "Figures"))
        for caption, path in figures:
            s.append(("figure", (caption, path)))
    headings = [payload for kind, payload in s if kind == "h2"]
    if len(headings) > 1:
        s.insert(1, ("toc", headings))
    return s


def render_markdown(
    metrics: Mapping[str, Any], figures: list[tuple[str, Path]], out_dir: Path
) -> str:
    lines = ["# ectskin reproduction report", ""]
    created = lookup(metrics, "created_utc")
    if created:
        lines += [f"_Created {created} by ectskin {__version__}._", ""]
    command = lookup(metrics, "command")
    if command:
        lines += [f"Made by `{command}`.", ""]
    for kind, payload in _sections(metrics, figures):
        if kind == "h2":
            lines += [f"## {payload}", ""]
        elif kind == "p":
            lines += [payload, ""]
        elif kind == "list":
            lines += [f"- {item}" for item in payload] + [""]
        elif kind == "toc":
            lines += ["**Contents**", ""]
            lines += [f"- [{title}](#{slug(title)})" for title in payload] + [""]
        elif kind == "table":
            lines += markdown_table(*payload) + [""]
        elif kind == "figure":
            caption, path = payload
            rel = _rel(path, out_dir)
            if FIGURE_SUFFIXES.get(path.suffix.lower()) is None:  # PDF: a link, not an image
                lines += [f"[{caption} ({path.suffix[1:].upper()})]({rel})", ""]
            else:
                lines += [f"![{caption}]({rel})", "", f"*{caption}*", ""]
    return "\n".join(lines)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
table{border-collapse:collapse;margin:0.5em 0 1.5em}th,td{border:1px solid #ccc;padding:4px 10px;
text-align:left;vertical-align:top}th{background:#f2f2f2}figure{margin:1.5em 0}
img{max-width:100%;border:1px solid #eee}figcaption{font-style:italic;color:#555}code{background:#f4f4f4}
"""


def render_html(
    metrics: Mapping[str, Any],
    figures: list[tuple[str, Path]],
    *,
    embed: bool = True,
    out_dir: Path | None = None,
) -> str:
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        "<title>ectskin reproduction report</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>ectskin reproduction report</h1>",
    ]
    created = lookup(metrics, "created_utc")
    if created:
        parts.append(f"<p><em>Created {html.escape(created)} by ectskin {__version__}.</em></p>")
    command = lookup(metrics, "command")
    if command:
        parts.append(f"<p>Made by <code>{html.escape(command)}</code>.</p>")
    for kind, payload in _sections(metrics, figures):
        if kind == "h2":
            parts.append(f'<h2 id="{slug(payload)}">{html.escape(payload)}</h2>')
        elif kind == "toc":
            items = "".join(f'<li><a href="#{slug(t)}">{html.escape(t)}</a></li>' for t in payload)
            parts.append(f"<nav><p><strong>Contents</strong></p><ul>{items}</ul></nav>")
        elif kind == "p":
            text = html.escape(payload)
            # `code` spans of the Markdown version
            while text.count("`") >= 2:
                text = text.replace("`", "<code>", 1).replace("`", "</code>", 1)
            parts.append(f"<p>{text}</p>")
        elif kind == "list":
            parts.append("<ul>" + "".join(f"<li>{html.escape(i)}</li>" for i in payload) + "</ul>")
        elif kind == "table":
            parts.append(_html_table(*payload))
        elif kind == "figure":
            caption, path = payload
            mime = FIGURE_SUFFIXES.get(path.suffix.lower())
            rel = html.escape(_rel(path, out_dir or path.parent))
            if mime is None:  # PDF: browsers do not show it as an image; link the file
                kind_name = path.suffix[1:].upper()
                parts.append(
                    f'<figure><a href="{rel}">{html.escape(caption)} ({kind_name})</a>'
                    f"<figcaption>{html.escape(caption)}</figcaption></figure>"
                )
                continue
            if embed:
                src = f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")
            else:
                src = rel
            parts.append(
                f'<figure><img src="{src}" alt="{html.escape(caption)}">'
                f"<figcaption>{html.escape(caption)}</figcaption></figure>"
            )
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(
    out_dir: str | Path,
    metrics: Mapping[str, Any],
    figures: Mapping[str, str | Path] | Sequence[str | Path] | None = None,
    *,
    embed_images: bool = True,
) -> tuple[Path, Path]:
    """Write ``out_dir/report.md`` and ``out_dir/report.html`` (atomically) from ``metrics``.

    Parameters
    ----------
    out_dir : path
        The output folder (must exist); figure paths are relative to it unless absolute.
    metrics : dict
        As written by ``ectskin reproduce`` to ``metrics.json`` (see the module docstring).
    figures : {caption: path} or [path], optional
        PNG, SVG or PDF figures to show (PDF ones are linked). The twin's Fig. 3/4
        (``characterize/fig3_inflation.*``, ``characterize/fig4_touch.*``) are added when
        present in ``out_dir``.
    embed_images : bool
        Embed the images into the HTML as base64 (self-contained file); otherwise link them.

    Returns
    -------
    (report.md path, report.html path)
    """
    out = Path(out_dir)
    if not out.is_dir():
        raise EctskinError(f"report output folder {out} does not exist")
    if not isinstance(metrics, Mapping):
        raise EctskinError(f"metrics must be a dict, got {type(metrics).__name__}")
    metrics = dict(metrics)
    metrics.setdefault("created_utc", datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"))
    figs = _collect_figures(out, figures)
    md_path, html_path = out / "report.md", out / "report.html"
    write_text_atomic(md_path, render_markdown(metrics, figs, out))
    write_text_atomic(html_path, render_html(metrics, figs, embed=embed_images, out_dir=out))
    log.info("wrote %s and %s (%d figures)", md_path, html_path, len(figs))
    return md_path, html_path
