"""The reproduction report: ``report.md`` and a self-contained ``report.html`` from a metrics dict.

The heart of the report is one table, "metric · paper · this run · baselines", that sets each
number of this run beside the paper's (§4) and beside the trivial baselines, followed by the margin
over the "markers do not move" baseline, the ablations, the timings, the machine and the figures.
Both files are written atomically. Markdown references images by relative path; the HTML embeds
them as base64 so it can be mailed around as one file.

The metrics dict is the one ``ectskin reproduce`` writes to ``metrics.json`` (every key optional;
a missing number shows as "—")::

    {"touch": {"accuracy", "n_test_frames", "n_misclassified", "misclassified",
               "n_misclassified_adjacent", "all_adjacent", "confusions",
               "baselines": {name: {"accuracy", "n_misclassified", ...}},
               "training": {"seconds", "epochs", "best_epoch", "device"},
               "robust": {"accuracy", "n_test_frames", "n_misclassified",
                          "n_misclassified_adjacent", "per_trial", "worst_trial",
                          "training": {..., "recipe"}}},
     "track": {"ad_mm_mean", "ad_mm_std", "n_test_samples", "n_test_trajectories",
               "examples": {"ad_mm": [...], "worst_ad_mm"}, "worst_trajectory",
               "baselines": {"no_motion": {"ad_mm_mean", "ad_mm_std"}, ...},
               "ablations": {"no_prior": {...}, "window_1": {...}},
               "training": {...}},
     "timings_s": {step: seconds}, "reused": [step, ...], "machine": {...},
     "profile": "quick" | "paper", "protocol": {...}, "created_utc": "..."}
"""

from __future__ import annotations

import base64
import html
import logging
import os
import platform
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ectskin import __version__
from ectskin._check import EctskinError

log = logging.getLogger(__name__)

#: The paper's numbers (§4), quoted in the report beside this run's.
PAPER = {
    "touch_accuracy_pct": 99.88,
    "touch_misclassified": "34 of 28 800",
    "touch_adjacent": "all",
    "track_ad_mm": (2.905, 2.207),
    "track_worst_example_mm": 3.754,
    "touch_training": "10 min on 1 GPU (Quadro P5000)",
    "track_training": "2.5 h on 3 GPUs (Quadro P5000)",
    "touch_split": "125 / 32 / 32 trials",
    "track_split": "108 / 18 / 20 trials",
}

#: Figures the twin's ``characterize`` step writes, included when present in the output folder.
CHARACTERIZE_FIGURES = (
    ("characterize/fig3_inflation.png", "Fig. 3: response to inflation (digital twin)"),
    ("characterize/fig4_touch.png", "Fig. 4: two-stage touch response (digital twin)"),
)

_BASELINE_NAMES = {
    "majority": "majority class",
    "logistic": "logistic regression",
    "logreg": "logistic regression",
    "random_forest": "random forest",
    "knn": "k-NN",
    "no_motion": "markers do not move",
    "ridge": "ridge regression",
}

_DASH = "—"
#: the report's name for the TouchMLP trained with the ``robust`` profile
ROBUST_LABEL = "TouchMLP, robust recipe (ours)"


# --------------------------------------------------------------------------- helpers
def _get(d: Any, path: str, default: Any = None) -> Any:
    """``_get(m, "track.baselines.no_motion.ad_mm_mean")``: nested lookup, ``default`` if absent."""
    cur = d
    for key in path.split("."):
        if not isinstance(cur, Mapping) or key not in cur or cur[key] is None:
            return default
        cur = cur[key]
    return cur


def _pct(x: Any, digits: int = 2) -> str:
    return _DASH if x is None else f"{100.0 * float(x):.{digits}f} %"


def _mm(mean: Any, std: Any = None) -> str:
    if mean is None:
        return _DASH
    return (
        f"{float(mean):.3f} ± {float(std):.3f} mm" if std is not None else f"{float(mean):.3f} mm"
    )


def _count(n_wrong: Any, n_total: Any) -> str:
    if n_wrong is None or n_total is None:
        return _DASH
    return f"{int(n_wrong):,} of {int(n_total):,}".replace(",", " ")


def _duration(seconds: Any) -> str:
    if seconds is None:
        return _DASH
    s = float(seconds)
    if s < 120:
        return f"{s:.1f} s"
    if s < 7200:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.2f} h"


def _baseline_name(key: str) -> str:
    return _BASELINE_NAMES.get(key, key.replace("_", " "))


def machine_info() -> dict[str, Any]:
    """What this run ran on: OS, Python, CPU count, torch version and GPU (if torch imports)."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "ectskin": __version__,
    }
    try:
        import torch

        info["torch"] = torch.__version__
        info["torch_threads"] = torch.get_num_threads()
        if torch.cuda.is_available():
            info["gpu"] = [torch.cuda.get_device_name(k) for k in range(torch.cuda.device_count())]
        else:
            info["gpu"] = []
    except ImportError:  # pragma: no cover - torch is a dependency
        info["torch"] = None
    return info


def _write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


# --------------------------------------------------------------------------- content
def results_table(metrics: Mapping[str, Any]) -> list[tuple[str, str, str, str]]:
    """The rows "metric · paper · this run · baselines" of the report, as plain strings."""
    rows: list[tuple[str, str, str, str]] = []
    t = _get(metrics, "touch", {})
    if t:
        tb = _get(t, "baselines", {}) or {}
        rows.append(
            (
                "Touch: test accuracy",
                f"{PAPER['touch_accuracy_pct']:.2f} %",
                _pct(_get(t, "accuracy")),
                "; ".join(f"{_baseline_name(k)} {_pct(_get(v, 'accuracy'))}" for k, v in tb.items())
                or _DASH,
            )
        )
        rows.append(
            (
                "Touch: misclassified test frames",
                PAPER["touch_misclassified"],
                _count(_get(t, "n_misclassified"), _get(t, "n_test_frames")),
                "; ".join(
                    f"{_baseline_name(k)} "
                    f"{_count(_get(v, 'n_misclassified'), _get(v, 'n_test_frames', _get(t, 'n_test_frames')))}"
                    for k, v in tb.items()
                )
                or _DASH,
            )
        )
        n_wrong, n_adj = _get(t, "n_misclassified"), _get(t, "n_misclassified_adjacent")
        if n_wrong is not None and n_adj is not None:
            adj = "none misclassified" if n_wrong == 0 else f"{n_adj} of {n_wrong}"
            rows.append(("Touch: confusions between adjacent regions", "all 34", adj, _DASH))
        r = _get(t, "robust", {})
        if r:
            n_wrong, n_adj = _get(r, "n_misclassified"), _get(r, "n_misclassified_adjacent")
            wrong = f"{_count(n_wrong, _get(r, 'n_test_frames'))} misclassified"
            if n_wrong and n_adj is not None:
                wrong += f", {'all' if n_adj == n_wrong else n_adj} between adjacent regions"
            rows.append(
                (
                    f"Touch: test accuracy, {ROBUST_LABEL}",
                    f"{PAPER['touch_accuracy_pct']:.2f} % (34 of 28 800 misclassified, all adjacent)",
                    f"{_pct(_get(r, 'accuracy'))} ({wrong})",
                    _DASH,
                )
            )
    k = _get(metrics, "track", {})
    if k:
        kb = _get(k, "baselines", {}) or {}
        rows.append(
            (
                "Tracking: average distance AD (Eq. 3)",
                _mm(*PAPER["track_ad_mm"]),
                _mm(_get(k, "ad_mm_mean"), _get(k, "ad_mm_std")),
                "; ".join(
                    f"{_baseline_name(b)} {_mm(_get(v, 'ad_mm_mean'), _get(v, 'ad_mm_std'))}"
                    for b, v in kb.items()
                )
                or _DASH,
            )
        )
        rows.append(
            (
                "Tracking: worst of 6 shown examples",
                _mm(PAPER["track_worst_example_mm"]),
                _mm(_get(k, "examples.worst_ad_mm")),
                _DASH,
            )
        )
        worst = _get(k, "worst_trajectory")
        if worst:
            rows.append(
                (
                    "Tracking: worst test trajectory (mean AD)",
                    _DASH,
                    f"{_mm(_get(worst, 'ad_mm_mean'))} ({_get(worst, 'name', '?')})",
                    _DASH,
                )
            )
    for task, key in (("Touch", "touch"), ("Tracking", "track")):
        sp = _get(metrics, f"{key}.split")
        if sp:
            n_test = _get(metrics, f"{key}.n_test_frames", _get(metrics, f"{key}.n_test_samples"))
            rows.append(
                (
                    f"{task}: trials train / val / test",
                    PAPER[f"{key}_split"],
                    " / ".join(str(_get(sp, k, "?")) for k in ("train", "val", "test"))
                    + (f" trials ({n_test:,} test frames)".replace(",", " ") if n_test else ""),
                    _DASH,
                )
            )
    for task, key, paper in (
        ("Touch", "touch", PAPER["touch_training"]),
        ("Touch (robust recipe)", "touch.robust", _DASH),
        ("Tracking", "track", PAPER["track_training"]),
    ):
        tr = _get(metrics, f"{key}.training")
        if tr:
            dev = _get(tr, "device")
            rows.append(
                (
                    f"{task}: training time",
                    paper,
                    f"{_duration(_get(tr, 'seconds'))}"
                    + (f" on {dev}" if dev else "")
                    + (f", {_get(tr, 'epochs')} epochs" if _get(tr, "epochs") else ""),
                    _DASH,
                )
            )
    return rows


def margin_text(metrics: Mapping[str, Any]) -> list[str]:
    """Sentences on the margin of each model over its trivial baseline (honest either way)."""
    out = []
    ad = _get(metrics, "track.ad_mm_mean")
    nm = _get(metrics, "track.baselines.no_motion.ad_mm_mean")
    if ad is not None and nm is not None and nm > 0:
        gain = nm - ad
        if gain > 0:
            out.append(
                f"C2DT's AD is {gain:.3f} mm below the 'markers do not move' baseline "
                f"({ad:.3f} vs {nm:.3f} mm, {100 * gain / nm:.1f} % lower)."
            )
        else:
            out.append(
                f"C2DT does NOT beat the 'markers do not move' baseline: AD {ad:.3f} mm vs "
                f"{nm:.3f} mm for predicting the initial coordinates."
            )
    acc = _get(metrics, "touch.accuracy")
    tb = _get(metrics, "touch.baselines", {}) or {}
    base = {k: _get(v, "accuracy") for k, v in tb.items() if _get(v, "accuracy") is not None}
    if acc is not None and base:
        best = max(base, key=base.get)
        maj = base.get("majority")
        text = (
            f"TouchMLP reaches {_pct(acc)} against {_pct(base[best])} for the best baseline "
            f"({_baseline_name(best)})"
        )
        if maj is not None and best != "majority":
            text += f" and {_pct(maj)} for always predicting the majority class"
        out.append(text + ".")
    racc = _get(metrics, "touch.robust.accuracy")
    if racc is not None and acc is not None:
        gain = racc - acc
        out.append(
            f"Trained with the robust recipe, the same TouchMLP reaches {_pct(racc)} on the same "
            f"test trials ({100 * gain:+.2f} points versus the paper's recipe)."
        )
    return out


def ablation_rows(metrics: Mapping[str, Any]) -> list[tuple[str, str, str, str]]:
    """Rows "variant · training epochs · AD · change vs the full model" for the tracking
    ablations."""
    k = _get(metrics, "track", {})
    abl = _get(k, "ablations", {}) or {}
    if not abl:
        return []
    full = _get(k, "ad_mm_mean")

    def epochs(v: Any) -> str:
        e = _get(v, "training.epochs")
        return _DASH if e is None else str(e)

    rows = [("C2DT (prior, 10 frames)", epochs(k), _mm(full, _get(k, "ad_mm_std")), _DASH)]
    labels = {
        "no_prior": "without prior knowledge (absolute calibration, no initial coordinates)",
        "window_1": "1 frame instead of 10",
    }
    for name, v in abl.items():
        a = _get(v, "ad_mm_mean")
        change = _DASH if a is None or full is None else f"{a - full:+.3f} mm"
        label = labels.get(name, name.replace("_", " "))
        rows.append((label, epochs(v), _mm(a, _get(v, "ad_mm_std")), change))
    return rows


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
    for rel, caption in CHARACTERIZE_FIGURES:
        path = out_dir / rel
        if path.is_file() and path.resolve() not in have:
            items.append((caption, path))
    return items


def _rel(path: Path, out_dir: Path) -> str:
    try:
        return path.resolve().relative_to(out_dir.resolve()).as_posix()
    except ValueError:
        return path.resolve().as_posix()


# --------------------------------------------------------------------------- render
def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
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
        "beside trivial baselines. A model is only as good as its margin over them."
    )
    prof = _get(metrics, "profile")
    if prof:
        intro += f" Training profile: `{prof}`."
    s.append(("p", intro))
    data = _get(metrics, "data")
    if isinstance(data, Mapping) and data:
        desc = ", ".join(f"{k}: {v}" for k, v in data.items())
        s.append(("p", f"Data: {desc}."))
    s.append(("h2", "Results"))
    s.append(("table", (("metric", "paper", "this run", "baselines"), results_table(metrics))))
    robust = _get(metrics, "touch.robust")
    if robust:
        from ectskin.learn.evaluate import describe_recipe

        recipe = describe_recipe(_get(robust, "training.recipe"))
        text = (
            f'"{ROBUST_LABEL}" is the paper\'s TouchMLP, unchanged, trained with the `robust` '
            f"profile instead of the paper's recipe: {recipe}. It is evaluated on the same test "
            "trials. On the twin the paper's recipe fits the training trials exactly and "
            "generalises poorly to unseen combinations of inflation state and touch placement; "
            "see docs/architecture.md."
        )
        s.append(("p", text))
    margins = margin_text(metrics)
    if margins:
        s.append(("h2", "Margin over the baselines"))
        s.append(("list", margins))
    confusions = _get(metrics, "touch.confusions") or []
    if confusions:
        rows = [
            (
                str(c.get("true")),
                str(c.get("pred")),
                str(c.get("count")),
                {True: "yes", False: "no"}.get(c.get("adjacent"), _DASH),
            )
            for c in confusions[:10]
        ]
        s.append(("h2", "Largest touch confusions"))
        s.append(("table", (("true class", "predicted", "frames", "adjacent regions"), rows)))
    abl = ablation_rows(metrics)
    if abl:
        s.append(("h2", "Tracking ablations"))
        s.append(("table", (("variant", "epochs", "AD (Eq. 3)", "change vs full model"), abl)))
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
    per_marker = _get(metrics, "track.per_marker") or {}
    if per_marker:
        rows = [
            (name, _mm(_get(v, "ad_mm_mean"), _get(v, "ad_mm_std")))
            for name, v in per_marker.items()
        ]
        s.append(("h2", "Tracking per marker"))
        s.append(("table", (("marker", "AD"), rows)))
    timings = _get(metrics, "timings_s") or {}
    if timings:
        reused = set(_get(metrics, "reused") or [])
        s.append(("h2", "Timings"))
        if reused:
            rows = [
                (step, _duration(sec), "reused (time of the earlier run)" if step in reused else "")
                for step, sec in timings.items()
            ]
            s.append(("table", (("step", "time", "reused"), rows)))
        else:
            rows = [(step, _duration(sec)) for step, sec in timings.items()]
            s.append(("table", (("step", "time"), rows)))
    machine = _get(metrics, "machine") or {}
    if machine:
        s.append(("h2", "Machine"))
        s.append(("table", (("", ""), [(k, str(v)) for k, v in machine.items()])))
    if figures:
        s.append(("h2", "Figures"))
        for caption, path in figures:
            s.append(("figure", (caption, path)))
    return s


def render_markdown(
    metrics: Mapping[str, Any], figures: list[tuple[str, Path]], out_dir: Path
) -> str:
    lines = ["# ectskin reproduction report", ""]
    created = _get(metrics, "created_utc")
    if created:
        lines += [f"_Created {created} by ectskin {__version__}._", ""]
    for kind, payload in _sections(metrics, figures):
        if kind == "h2":
            lines += [f"## {payload}", ""]
        elif kind == "p":
            lines += [payload, ""]
        elif kind == "list":
            lines += [f"- {item}" for item in payload] + [""]
        elif kind == "table":
            lines += _md_table(*payload) + [""]
        elif kind == "figure":
            caption, path = payload
            lines += [f"![{caption}]({_rel(path, out_dir)})", "", f"*{caption}*", ""]
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
    created = _get(metrics, "created_utc")
    if created:
        parts.append(f"<p><em>Created {html.escape(created)} by ectskin {__version__}.</em></p>")
    for kind, payload in _sections(metrics, figures):
        if kind == "h2":
            parts.append(f"<h2>{html.escape(payload)}</h2>")
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
            if embed:
                mime = "image/svg+xml" if path.suffix.lower() == ".svg" else "image/png"
                src = f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")
            else:
                src = html.escape(_rel(path, out_dir or path.parent))
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
        PNG/SVG figures to show. The twin's Fig. 3/4 (``characterize/fig3_inflation.png``,
        ``characterize/fig4_touch.png``) are added when present in ``out_dir``.
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
    _write_text_atomic(md_path, render_markdown(metrics, figs, out))
    _write_text_atomic(html_path, render_html(metrics, figs, embed=embed_images, out_dir=out))
    log.info("wrote %s and %s (%d figures)", md_path, html_path, len(figs))
    return md_path, html_path
