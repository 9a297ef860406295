"""The report's contact sections: where, how hard and how many fingers, and ECT images.

Each number stands beside the goal of issue 10, beside the strongest baseline scored on the
same test frames, with the margin, and, where metrics.json carries a ``bound`` block, beside the
physical limit (the Cramér–Rao bound at the test frames' true points); nothing here computes a
metric, it only words metrics.json's ``contact``, ``multi``, ``bound`` and ``ect_image`` blocks
(and, through :mod:`ectskin.report.inversion`, ``inversion``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ectskin.report.inversion import inversion_sections
from ectskin.report.wording import DASH, baseline_name, lookup, pct

#: the goals of the contact work (issue 10), beside each number
GOALS = {
    "loc_mm_mean": "≤ 3 mm at every inflation state",
    "force_mae_n": "≤ 0.2 N",
    "hover_detect_mm": "≥ 5 mm",
    "count_accuracy": "≥ 95 %",
    "ect_loc": "≤ 2 × the learned model's error",
}
#: (key, label, unit, lower is better)
CONTACT_ROWS = (
    ("loc_mm_mean", "Contact point: mean error", "mm", True),
    ("loc_mm_median", "Contact point: median error", "mm", True),
    ("loc_mm_p90", "Contact point: 90th percentile error", "mm", True),
    ("face_accuracy", "Face (front / back) right", "%", False),
    ("force_mae_n", "Force: mean absolute error", "N", True),
    ("force_rel", "Force: MAE / mean force", "%", True),
    ("hover_detect_mm", "Hover detected up to (≥ 90 % of frames)", "mm", False),
    ("contact_accuracy", "Touch / no touch right", "%", False),
)


#: rows of the manual handling on / off table: the contact rows that matter most, and the count
HANDLING_ROWS = tuple(
    row
    for row in CONTACT_ROWS
    if row[0] in ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "force_mae_n", "hover_detect_mm")
) + (("count_accuracy", "Finger count right", "%", False),)


def _value(v: Any, unit: str) -> str:
    if not isinstance(v, int | float):
        return DASH
    if unit == "%":
        return pct(v)
    if unit == "N":
        return f"{v:.3f} N"
    return f"{v:.2f} mm"


def _best(baselines: Mapping[str, Any], key: str, lower: bool) -> tuple[str, float] | None:
    found = [(k, v.get(key)) for k, v in baselines.items() if isinstance(v.get(key), int | float)]
    if not found:
        return None
    return min(found, key=lambda kv: kv[1]) if lower else max(found, key=lambda kv: kv[1])


def _margin(model: Any, best: tuple[str, float] | None, unit: str, lower: bool) -> str:
    if best is None or not isinstance(model, int | float):
        return DASH
    diff = best[1] - model if lower else model - best[1]
    if unit == "%":
        return f"{'+' if diff >= 0 else '−'}{abs(diff) * 100:.1f} points"
    return f"{'better' if diff >= 0 else 'worse'} by {_value(abs(diff), unit)}"


#: which reduction of the bound at the test frames (metrics.json ``bound.test``) stands beside
#: each contact metric; a metric not named has no bound
BOUND_OF = {
    "loc_mm_mean": ("loc_mm_mean", "mm"),
    "loc_mm_median": ("loc_mm_median", "mm"),
    "force_mae_n": ("force_n_mean", "N"),
}


def _bound_cell(bound_test: Mapping[str, Any] | None, key: str) -> str:
    if not bound_test or key not in BOUND_OF:
        return DASH
    name, unit = BOUND_OF[key]
    return _value(bound_test.get(name), unit)


def contact_table(
    block: Mapping[str, Any],
    rows=CONTACT_ROWS,
    goals: Mapping[str, str] = GOALS,
    bound_test: Mapping[str, Any] | None = None,
) -> list[tuple[str, ...]]:
    """Rows "metric · goal · model · strongest baseline · margin" of a contact-like block, and
    "· bound" when ``bound_test`` (metrics.json's ``bound.test``) is given."""
    baselines = lookup(block, "baselines") or {}
    out: list[tuple[str, ...]] = []
    for key, label, unit, lower in rows:
        model = block.get(key)
        best = _best(baselines, key, lower)
        row = (
            label,
            goals.get(key, DASH),
            _value(model, unit),
            f"{baseline_name(best[0])} {_value(best[1], unit)}" if best else DASH,
            _margin(model, best, unit, lower),
        )
        out.append(row + ((_bound_cell(bound_test, key),) if bound_test is not None else ()))
    return out


def per_state_table(
    per_state: Mapping[str, Any],
    baselines: Mapping[str, Any],
    bound_states: Mapping[str, Any] | None,
) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """(header, rows) of the per-state errors: state · mean · p90 · strongest baseline's mean ·
    frames, and with ``bound_states`` (metrics.json ``bound.per_state``) the bound at the
    state's test frames (position, force); a state without a field shows "—" there."""
    rows = []
    for name, v in per_state.items():
        base = {
            b: x for b, bv in baselines.items()
            if isinstance(x := ((bv.get("per_state") or {}).get(name) or {}).get("loc_mm_mean"),
                          int | float)
        }
        best = min(base.items(), key=lambda kv: kv[1]) if base else None
        row: tuple[str, ...] = (
            name,
            _value(v.get("loc_mm_mean"), "mm"),
            _value(v.get("loc_mm_p90"), "mm"),
            f"{baseline_name(best[0])} {_value(best[1], 'mm')}" if best else DASH,
        )
        if bound_states is not None:
            test = (bound_states.get(name) or {}).get("test") or {}
            row += (_value(test.get("loc_mm_mean"), "mm"), _value(test.get("force_n_mean"), "N"))
        rows.append(row + (str(v.get("n_frames")),))
    head: tuple[str, ...] = ("state", "mean", "p90", "strongest baseline")
    if bound_states is not None:
        head += ("bound (CRB)", "force bound")
    return head + ("frames",), rows


def _share(x: Any) -> str:
    return pct(x) if isinstance(x, int | float) else DASH


#: the parts of the force split (metrics.json ``contact.force_split``) and their words
FORCE_PARTS = (
    ("observable", "observable (bound < {thr:g} N)"),
    ("not_observable", "not observable (bound ≥ {thr:g} N)"),
    ("no_bound", "no bound (no field at the frame's state)"),
)


def force_split_section(c: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """Where force can be known: the answering model's force MAE, the strongest baseline's and
    the model's σ coverage over the test frames (one finger) where the bound says force is
    observable, where it says it is not, and where there is none (``contact.force_split``);
    [] without the split."""
    split = c.get("force_split")
    if not isinstance(split, Mapping) or not split.get("models"):
        return []
    thr = split.get("threshold_n") or 0.1
    models = split["models"]
    own = models.get(split.get("model")) or {}
    others = {k: v for k, v in models.items() if k != split.get("model")}
    rows = []
    for part, label in FORCE_PARTS:
        key = f"force_mae_n_{part}"
        best = _best(others, key, True)
        rows.append((
            label.format(thr=thr),
            _share(own.get(f"share_{part}")),
            _value(own.get(key), "N"),
            f"{baseline_name(best[0])} {_value(best[1], 'N')}" if best else DASH,
            _value(own.get(f"bound_force_n_mean_{part}"), "N"),
            f"{_share(own.get(f'force_coverage_1sigma_{part}'))} / "
            f"{_share(own.get(f'force_coverage_2sigma_{part}'))}",
        ))
    cov1, cov2 = c.get("force_coverage_1sigma"), c.get("force_coverage_2sigma")
    text = (
        f"Force where it can be known: the test frames with one finger on the skin, split by the "
        f"bound on the force's standard deviation at each frame's true point and force (case "
        f"`{split.get('case') or DASH}`, the bound section's), at {thr:g} N. Where the bound is "
        "above it, no unbiased estimate from one frame comes within it: this layout cannot tell "
        "the force there, and an error near the spread of the forces is the honest answer. "
        "Every force comes with the model's own standard deviation σ; a calibrated σ holds the "
        "true force within ±1σ / ±2σ in about 68 % / 95 % of the frames"
        + (f" (all frames: {_share(cov1)} / {_share(cov2)})." if isinstance(cov1, int | float)
           and isinstance(cov2, int | float) else ".")
    )
    head = ("frames", "share", "this run's MAE", "strongest baseline", "mean bound",
            "within ±1σ / ±2σ")
    return [("p", text), ("table", (head, rows))]


def bound_sections(metrics: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The physical limit's words and per-state table (metrics.json ``bound``); [] without it."""
    b = lookup(metrics, "bound")
    if not isinstance(b, Mapping) or not b:
        return []
    s: list[tuple[str, Any]] = [("h2", "The physical limit: Cramér–Rao bound")]
    settings = b.get("settings") or {}
    case = b.get("case")
    nuis = list(settings.get("nuisances") or [])
    known = {
        "none": "every nuisance known",
        "all": f"the nuisances ({', '.join(nuis)}) estimated alongside, within their priors",
    }.get(str(case), f"the nuisance {case} estimated alongside, within its prior")
    window = lookup(metrics, "contact.window")
    tested = bool((b.get("test") or {}).get("n_points"))
    s.append((
        "p",
        "The Cramér–Rao bound is the least root-mean-square error any unbiased estimator can "
        "reach from one frame of readouts, given each pair's noise (docs/bound.md). Here it is "
        f"taken from the response field of each contact state with {known} (case `{case}`)"
        + (", at each test frame's true point and force" if tested else "")
        + ". A mean or median error may lie somewhat below a root-mean-square bound, and a "
        "model that reads several frames"
        + (f" (ContactNet reads {window})" if isinstance(window, int) else "")
        + " of a still finger can go below the one-frame bound by up to the square root of "
        "their number; a model far above it has room to learn.",
    ))
    thr = settings.get("force_threshold_n") or 0.1
    near, away = b.get("force_observable_share_near_wires"), b.get("force_observable_share_away_from_wires")
    faces = b.get("per_face") or {}
    where = "; ".join(
        f"{f} face {_share(v.get('force_observable_share'))}" for f, v in faces.items()
    )
    if isinstance(b.get("force_observable_share"), int | float):
        s.append((
            "p",
            f"Force is observable (bound < {thr:g} N at {settings.get('force_n', DASH)} N) on "
            f"{_share(b.get('force_observable_share'))} of the faces' map cells over all states"
            + (f" ({where})" if where else "")
            + (
                f": on {_share(near)} of the cells within {settings.get('near_wire_mm', DASH)} mm "
                f"of a wire and on {_share(away)} of those farther from every wire"
                if isinstance(near, int | float) and isinstance(away, int | float) else ""
            )
            + f". Where it is not, no unbiased estimate from one frame comes within {thr:g} N of "
            "the force (root mean square).",
        ))
    rows = [
        (name, _value(v.get("loc_mm_mean"), "mm"), _value(v.get("force_n_mean"), "N"),
         _share(v.get("force_observable_share")))
        for name, v in (b.get("per_state") or {}).items()
    ]
    if rows:
        s.append(("p", f"Over the whole faces (map cells, {settings.get('force_n', DASH)} N), "
                       "per inflation state:"))
        s.append(("table", (("state", "position bound", "force bound", "force observable"),
                            rows)))
    missing = (b.get("test") or {}).get("states_without_field") or {}
    if missing:
        s.append(("p", "Test frames without a response field (not bounded): "
                       + ", ".join(f"{k} ({n} frames)" for k, n in missing.items()) + "."))
    return s


def handling_table(
    on: Mapping[str, Any], on_multi: Mapping[str, Any], off: Mapping[str, Any]
) -> list[tuple[str, ...]]:
    """Rows "metric · hand on · hand off · strongest baseline on · off" (the count accuracy of
    the hand-on run is in ``multi``)."""
    rows = []
    for key, label, unit, lower in HANDLING_ROWS:
        src = on_multi if key == "count_accuracy" else on
        cells = [label, _value(src.get(key), unit), _value(off.get(key), unit)]
        for block in (src, off):
            best = _best(block.get("baselines") or {}, key, lower)
            cells.append(f"{baseline_name(best[0])} {_value(best[1], unit)}" if best else DASH)
        rows.append(tuple(cells))
    return rows


def candidate_sections(metrics: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The touch run's model choice (``--touch-model auto``): every candidate's validation and
    test accuracy, the selected one marked (selection on validation only)."""
    cands = lookup(metrics, "touch.candidates")
    if not isinstance(cands, Mapping) or not cands:
        return []
    rows = [
        (
            name + (" (selected)" if v.get("selected") else ""),
            pct(v.get("val_accuracy")),
            pct(v.get("test_accuracy")),
        )
        for name, v in cands.items()
    ]
    text = (
        "The touch run chose its model on the validation split among these candidates "
        "(docs/model-choice.md); the test accuracy of each is shown, none was used to choose. "
        f"The touch results above are those of `{lookup(metrics, 'touch.selected_model')}`."
    )
    return [
        ("h2", "Touch model choice"),
        ("p", text),
        ("table", (("candidate", "validation", "test"), rows)),
    ]


def contact_sections(metrics: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The report's (kind, payload) items for ``contact``, ``multi`` and ``ect_image``."""
    s: list[tuple[str, Any]] = list(candidate_sections(metrics))
    c = lookup(metrics, "contact")
    header = ("metric", "goal", "this run", "strongest baseline", "margin")
    if isinstance(c, Mapping) and c:
        s.append(("h2", "Contact: where and how hard (beyond the paper)"))
        s.append(
            (
                "p",
                "ContactNet (ours) reads a window of calibrated frames and gives the finger count, "
                "each finger's face, point (mm) and force (N), and whether a finger hovers. It "
                "is trained and tested, split by trial, on the paper's trials together with the "
                "contact experiment (contact.h5: the paper's finger, forces and handling; chambers "
                "at their lowest and highest level; touches anywhere in the region, lifts, hover "
                "and a second finger). "
                "Errors are distances over the skin at rest: on one face the distance in (u, v); "
                "a point on the wrong face is charged the way around the body's side edge (the "
                "same rule as the ECT images below). Baselines: "
                + ", ".join(baseline_name(b) for b in (c.get("baselines") or {}))
                + " (the region centre is the touch classifier's answer turned into a point)."
                + (
                    f" The fingers were placed at {c['n_touch_points']} distinct points."
                    if isinstance(c.get("n_touch_points"), int)
                    else ""
                ),
            )
        )
        bound_test = lookup(metrics, "bound.test")
        has_bound = isinstance(bound_test, Mapping) and bool(bound_test.get("n_points"))
        if has_bound:
            s.append(("table", (header + ("bound (CRB)",), contact_table(c, bound_test=bound_test))))
        else:
            s.append(("table", (header, contact_table(c))))
        s.extend(force_split_section(c))
        per_state = c.get("per_state") or {}
        if per_state:
            s.append(("p", "Contact point error per inflation state (chamber volumes)" + (
                ", beside the strongest baseline's and the physical limit at the same states' "
                "test frames (the bound's section below):" if has_bound else ":")))
            bound_states = lookup(metrics, "bound.per_state", {}) if has_bound else None
            s.append(("table", per_state_table(per_state, c.get("baselines") or {},
                                               bound_states)))
        per_face = c.get("per_face") or {}
        if per_face:
            rows: list[tuple[str, ...]] = [
                (
                    name,
                    _value(v.get("loc_mm_mean"), "mm"),
                    _value(v.get("loc_mm_median"), "mm"),
                    str(v.get("n_frames")),
                )
                for name, v in per_face.items()
            ]
            s.append(("table", (("face", "mean", "median", "frames"), rows)))
        off = c.get("handling_off")
        if isinstance(off, Mapping) and off:
            s.append(
                (
                    "p",
                    "Manual handling on and off: the same test trials simulated again without the "
                    "experimenter's hand (each trial's finger, inflation and readout noise are the "
                    "same draw); the models were trained with the hand on, and the baselines "
                    "are fitted on the same training trials.",
                )
            )
            head = ("metric", "hand on", "hand off", "strongest baseline, on", "… off")
            multi_on = lookup(metrics, "multi") or {}
            s.append(("table", (head, handling_table(c, multi_on, off))))
    s.extend(bound_sections(metrics))
    s.extend(inversion_sections(metrics))
    multi = lookup(metrics, "multi")
    if isinstance(multi, Mapping) and multi and multi.get("count_accuracy") is not None:
        s.append(("h2", "Two fingers"))
        multi_rows = (
            ("count_accuracy", "Finger count (0, 1, 2) right", "%", False),
            ("loc_mm_mean", "Per finger, matched (Hungarian): mean error", "mm", True),
            ("loc_mm_p90", "Per finger, matched: 90th percentile", "mm", True),
        )
        goals = {"count_accuracy": GOALS["count_accuracy"]}
        s.append(("table", (header, contact_table(multi, multi_rows, goals))))
        by_true = multi.get("count_accuracy_by_true") or {}
        if by_true:
            s.append(
                (
                    "p",
                    "Count right, by the true count: "
                    + "; ".join(
                        f"{k} finger(s) {pct(v)}" for k, v in by_true.items() if v is not None
                    )
                    + f". Two-finger test frames: {multi.get('n_two_finger_frames', DASH)}.",
                )
            )
    ect = lookup(metrics, "ect_image")
    if isinstance(ect, Mapping) and ect:
        s.append(("h2", "ECT images without training"))
        learned = lookup(metrics, "contact.loc_mm_mean")
        settings = ect.get("settings") or {}
        s.append(
            (
                "p",
                "Images from the readouts alone (no training data): the change of each frame "
                "from the no-contact readout of its inflation state, reconstructed with the "
                "sensitivity (Jacobian) of the current deformation from the method of moments "
                f"(voxel kind: {settings.get('kind', DASH)}; a grounded conductor is how the "
                "finger acts), located at the image's "
                f"{settings.get('localisation', DASH)}. Goal: "
                + GOALS["ect_loc"]
                + (f" (here ≤ {2 * learned:.2f} mm)." if isinstance(learned, int | float) else "."),
            )
        )
        rows = []
        for name, v in (ect.get("methods") or {}).items():
            ratio = (
                f"{v['loc_mm_mean'] / learned:.1f} ×"
                if isinstance(learned, int | float)
                and isinstance(v.get("loc_mm_mean"), int | float)
                else DASH
            )
            rows.append(
                (
                    name,
                    _value(v.get("loc_mm_mean"), "mm"),
                    _value(v.get("loc_mm_median"), "mm"),
                    pct(v.get("face_accuracy")) if v.get("face_accuracy") is not None else DASH,
                    ratio,
                )
            )
        rows.append(
            (
                "ContactNet (learned)",
                _value(learned, "mm"),
                _value(lookup(metrics, "contact.loc_mm_median"), "mm"),
                pct(lookup(metrics, "contact.face_accuracy")),
                "1.0 ×",
            )
        )
        s.append(("table", (("method", "mean error", "median", "face right", "× learned"), rows)))
        timing = ect.get("timing") or {}
        jac = timing.get("jacobian_s_per_state")
        per_frame = timing.get("reconstruct_us_per_frame") or {}
        if jac is not None or per_frame:
            parts = [f"sensitivity {jac:.2f} s per inflation state"] if jac is not None else []
            parts += [f"{m} {us:.0f} µs per frame" for m, us in per_frame.items()]
            s.append(("p", "Timing (this run, on its machine): " + "; ".join(parts) + "."))
    return s
