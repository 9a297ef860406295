"""The report's tables and sentences from a metrics dict: this run beside the paper's numbers
(§4) and beside the baselines scored on the same test split, the margin over the strongest of
them, the tracking ablations."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypedDict

from ectskin.report.wording import (
    DASH,
    baseline_name,
    count,
    duration,
    lookup,
    mm,
    pct,
)


class PaperNumbers(TypedDict):
    touch_accuracy_pct: float
    touch_misclassified: str
    touch_adjacent: str
    track_ad_mm: tuple[float, float]  # (mean, std)
    track_worst_example_mm: float
    touch_training: str
    track_training: str
    touch_split: str
    track_split: str


#: The paper's numbers (§4), quoted in the report beside this run's.
PAPER: PaperNumbers = {
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

#: the report's name for the TouchMLP trained with the ``robust`` profile
ROBUST_LABEL = "TouchMLP, robust recipe (ours)"
#: the report's names of the tracking ablations (``track.ablations`` keys)
ABLATION_LABELS = {
    "no_prior": "without prior knowledge (absolute calibration, no initial coordinates)",
    "window_1": "1 frame instead of 10",
}


def results_table(metrics: Mapping[str, Any]) -> list[tuple[str, str, str, str]]:
    """The rows "metric · paper · this run · baselines" of the report, as plain strings."""
    rows: list[tuple[str, str, str, str]] = []
    t = lookup(metrics, "touch", {})
    if t:
        tb = lookup(t, "baselines", {}) or {}
        rows.append(
            (
                "Touch: test accuracy",
                f"{PAPER['touch_accuracy_pct']:.2f} %",
                pct(lookup(t, "accuracy")),
                "; ".join(f"{baseline_name(k)} {pct(lookup(v, 'accuracy'))}" for k, v in tb.items())
                or DASH,
            )
        )
        rows.append(
            (
                "Touch: misclassified test frames",
                PAPER["touch_misclassified"],
                count(lookup(t, "n_misclassified"), lookup(t, "n_test_frames")),
                "; ".join(
                    f"{baseline_name(k)} "
                    f"{count(lookup(v, 'n_misclassified'), lookup(v, 'n_test_frames', lookup(t, 'n_test_frames')))}"
                    for k, v in tb.items()
                )
                or DASH,
            )
        )
        n_wrong, n_adj = lookup(t, "n_misclassified"), lookup(t, "n_misclassified_adjacent")
        if n_wrong is not None and n_adj is not None:
            adj = "none misclassified" if n_wrong == 0 else f"{n_adj} of {n_wrong}"
            rows.append(("Touch: confusions between adjacent regions", "all 34", adj, DASH))
        r = lookup(t, "robust", {})
        if r:
            n_wrong, n_adj = lookup(r, "n_misclassified"), lookup(r, "n_misclassified_adjacent")
            wrong = f"{count(n_wrong, lookup(r, 'n_test_frames'))} misclassified"
            if n_wrong and n_adj is not None:
                wrong += f", {'all' if n_adj == n_wrong else n_adj} between adjacent regions"
            rows.append(
                (
                    f"Touch: test accuracy, {ROBUST_LABEL}",
                    f"{PAPER['touch_accuracy_pct']:.2f} % (34 of 28 800 misclassified, all adjacent)",
                    f"{pct(lookup(r, 'accuracy'))} ({wrong})",
                    "; ".join(
                        f"{baseline_name(k)} {pct(lookup(v, 'accuracy'))}"
                        for k, v in (lookup(r, "baselines", {}) or {}).items()
                    )
                    or DASH,
                )
            )
    k = lookup(metrics, "track", {})
    if k:
        kb = lookup(k, "baselines", {}) or {}
        rows.append(
            (
                "Tracking: average distance AD (Eq. 3)",
                mm(*PAPER["track_ad_mm"]),
                mm(lookup(k, "ad_mm_mean"), lookup(k, "ad_mm_std")),
                "; ".join(
                    f"{baseline_name(b)} {mm(lookup(v, 'ad_mm_mean'), lookup(v, 'ad_mm_std'))}"
                    for b, v in kb.items()
                )
                or DASH,
            )
        )
        rows.append(
            (
                "Tracking: worst of 6 shown examples",
                mm(PAPER["track_worst_example_mm"]),
                mm(lookup(k, "examples.worst_ad_mm")),
                DASH,
            )
        )
        worst = lookup(k, "worst_trajectory")
        if worst:
            rows.append(
                (
                    "Tracking: worst test trajectory (mean AD)",
                    DASH,
                    f"{mm(lookup(worst, 'ad_mm_mean'))} ({lookup(worst, 'name', '?')})",
                    DASH,
                )
            )
    for task, key, paper_split in (
        ("Touch", "touch", PAPER["touch_split"]),
        ("Tracking", "track", PAPER["track_split"]),
    ):
        sp = lookup(metrics, f"{key}.split")
        if sp:
            n_test = lookup(
                metrics, f"{key}.n_test_frames", lookup(metrics, f"{key}.n_test_samples")
            )
            rows.append(
                (
                    f"{task}: trials train / val / test",
                    paper_split,
                    " / ".join(str(lookup(sp, k, "?")) for k in ("train", "val", "test"))
                    + (f" trials ({n_test:,} test frames)".replace(",", " ") if n_test else ""),
                    DASH,
                )
            )
    for task, key, paper in (
        ("Touch", "touch", PAPER["touch_training"]),
        ("Touch (robust recipe)", "touch.robust", DASH),
        ("Tracking", "track", PAPER["track_training"]),
    ):
        tr = lookup(metrics, f"{key}.training")
        if tr:
            dev = lookup(tr, "device")
            rows.append(
                (
                    f"{task}: training time",
                    paper,
                    f"{duration(lookup(tr, 'seconds'))}"
                    + (f" on {dev}" if dev else "")
                    + (f", {lookup(tr, 'epochs')} epochs" if lookup(tr, "epochs") else ""),
                    DASH,
                )
            )
    return rows


def strongest_baseline(metrics: Mapping[str, Any], task: str) -> tuple[str, float] | None:
    """The strongest baseline of ``task`` ("touch": highest accuracy; "track": lowest AD), as
    (name, score), from the baselines scored on the model's own test split; None without any."""
    key, best = ("accuracy", max) if task == "touch" else ("ad_mm_mean", min)
    scores = {
        name: float(lookup(v, key))
        for name, v in (lookup(metrics, f"{task}.baselines", {}) or {}).items()
        if lookup(v, key) is not None
    }
    if not scores:
        return None
    name = best(scores, key=scores.__getitem__)
    return name, scores[name]


def margin_text(metrics: Mapping[str, Any]) -> list[str]:
    """Sentences on each model's margin over the *strongest* baseline scored on the same test
    split (honest either way: a model that loses says so, and by how much)."""
    out = []
    ad = lookup(metrics, "track.ad_mm_mean")
    best_track = strongest_baseline(metrics, "track")
    if ad is not None and best_track is not None:
        name, b = best_track
        label = f"the strongest baseline on the same test split, '{baseline_name(name)}'"
        diff = float(ad) - b
        rel = f", {100 * abs(diff) / b:.1f} %" if b > 0 else ""
        if diff < 0:
            text = f"C2DT's AD is {-diff:.3f} mm below {label} ({ad:.3f} vs {b:.3f} mm{rel} lower)"
        else:
            text = (
                f"C2DT does NOT beat {label}: it loses by {diff:.3f} mm (AD {ad:.3f} vs "
                f"{b:.3f} mm{rel} higher)"
            )
        nm = lookup(metrics, "track.baselines.no_motion.ad_mm_mean")
        if nm is not None and name != "no_motion":
            text += (
                f"; 'markers do not move' (the initial coordinates as the answer) gives "
                f"{float(nm):.3f} mm"
            )
        out.append(text + ".")
    acc = lookup(metrics, "touch.accuracy")
    best_touch = strongest_baseline(metrics, "touch")
    if acc is not None and best_touch is not None:
        name, b = best_touch
        label = f"the strongest baseline on the same test split, '{baseline_name(name)}'"
        diff = 100 * (float(acc) - b)
        if diff > 0:
            text = f"TouchMLP reaches {pct(acc)}, {diff:.2f} points above {label} ({pct(b)})"
        else:
            text = (
                f"TouchMLP does NOT beat {label}: {pct(acc)} against {pct(b)} "
                f"({-diff:.2f} points lower)"
            )
        maj = lookup(metrics, "touch.baselines.majority.accuracy")
        if maj is not None and name != "majority":
            text += f"; always predicting the majority class gives {pct(maj)}"
        out.append(text + ".")
    racc = lookup(metrics, "touch.robust.accuracy")
    if racc is not None and acc is not None:
        gain = racc - acc
        text = (
            f"Trained with the robust recipe, the same TouchMLP reaches {pct(racc)} on the same "
            f"test trials ({100 * gain:+.2f} points versus the paper's recipe"
        )
        own = _best_accuracy(lookup(metrics, "touch.robust.baselines", {}) or {})
        if own is not None:  # the baselines fitted on the robust run's own calibrated inputs
            name, b = own
            extra = lookup(metrics, "touch.robust.training.recipe.extra_train") or []
            text += (
                f", {100 * (racc - b):+.2f} points versus '{baseline_name(name)}' on the same "
                "calibrated inputs" + (" and training trials" if extra else "")
            )
        elif best_touch is not None:
            name, b = best_touch
            text += f", {100 * (racc - b):+.2f} points versus '{baseline_name(name)}'"
        out.append(text + ").")
    return out


def _best_accuracy(baselines: Mapping[str, Any]) -> tuple[str, float] | None:
    """(name, accuracy) of the most accurate of ``baselines`` ({name: metrics}), None if none."""
    scored = [(k, float(v["accuracy"])) for k, v in baselines.items()
              if isinstance(v, Mapping) and v.get("accuracy") is not None]
    return max(scored, key=lambda kv: kv[1]) if scored else None


def ablation_note(metrics: Mapping[str, Any]) -> str | None:
    """A sentence that sets the ablations beside the strongest tracking baseline of the same
    test split (the ablations are trained on the same trials and tested on the same ones)."""
    best = strongest_baseline(metrics, "track")
    abl = lookup(metrics, "track.ablations", {}) or {}
    if best is None or not abl:
        return None
    name, b = best
    scored = [k for k, v in abl.items() if lookup(v, "ad_mm_mean") is not None]
    losing = [k for k in scored if float(lookup(abl[k], "ad_mm_mean")) >= b]
    text = (
        f"For scale: the strongest baseline on the same test split, '{baseline_name(name)}', "
        f"reaches {b:.3f} mm"
    )
    if losing:
        names = "; ".join(ABLATION_LABELS.get(k, k).split(" (")[0] for k in losing)
        text += f". Variants that do NOT beat it: {names}"
    return text + "."


def ablation_rows(metrics: Mapping[str, Any]) -> list[tuple[str, str, str, str]]:
    """Rows "variant · training epochs · AD · change vs the full model" for the tracking
    ablations."""
    k = lookup(metrics, "track", {})
    abl = lookup(k, "ablations", {}) or {}
    if not abl:
        return []
    full = lookup(k, "ad_mm_mean")

    def epochs(v: Any) -> str:
        e = lookup(v, "training.epochs")
        return DASH if e is None else str(e)

    rows = [("C2DT (prior, 10 frames)", epochs(k), mm(full, lookup(k, "ad_mm_std")), DASH)]
    for name, v in abl.items():
        a = lookup(v, "ad_mm_mean")
        change = DASH if a is None or full is None else f"{a - full:+.3f} mm"
        label = ABLATION_LABELS.get(name, name.replace("_", " "))
        rows.append((label, epochs(v), mm(a, lookup(v, "ad_mm_std")), change))
    return rows
