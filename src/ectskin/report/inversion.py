"""The report's section on the training-free physical inversion: its errors beside ContactNet's,
the strongest baseline's and the physical limit's, overall and per inflation state, where force
is observable, its time per frame, and the contact model chosen for the states with a field
(the run's model, its baselines, the inversion or the hybrid). It only words metrics.json's
``inversion`` block (with ``contact``, ``multi`` and ``bound`` for the comparisons); nothing
here computes a metric.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ectskin.report.wording import DASH, baseline_name, lookup, pct

#: the live engine's budget per frame (ms, one core; issue 20)
LIVE_MS = 2.0


def _mm(v: Any) -> str:
    return f"{v:.2f} mm" if isinstance(v, int | float) else DASH


def _n(v: Any) -> str:
    return f"{v:.3f} N" if isinstance(v, int | float) else DASH


def _pct(v: Any) -> str:
    return pct(v) if isinstance(v, int | float) else DASH


def _best(values: Mapping[str, Any], lower: bool = True) -> str:
    """"k-NN 3.10 mm" of the best of {baseline: number}, "—" without one."""
    found: list[tuple[str, float]] = [
        (k, float(v)) for k, v in (values or {}).items() if isinstance(v, int | float)]
    if not found:
        return DASH
    k, v = min(found, key=lambda kv: kv[1]) if lower else max(found, key=lambda kv: kv[1])
    return f"{baseline_name(k)} {_mm(v)}"


def _best_of(baselines: Mapping[str, Any], key: str, fmt, lower: bool) -> str:
    found: list[tuple[str, float]] = [
        (b, float(v[key])) for b, v in (baselines or {}).items()
        if isinstance(v, Mapping) and isinstance(v.get(key), int | float)]
    if not found:
        return DASH
    k, v = min(found, key=lambda kv: kv[1]) if lower else max(found, key=lambda kv: kv[1])
    return f"{baseline_name(k)} {fmt(v)}"


def inversion_table(metrics: Mapping[str, Any]) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """(header, rows) "metric · inversion · ContactNet · strongest baseline · bound (CRB)". The
    point error of ContactNet and the baselines is theirs on the states the inversion covers;
    force, count and hover are theirs over all test frames (the same when every test state has a
    field)."""
    inv = lookup(metrics, "inversion") or {}
    c = lookup(metrics, "contact") or {}
    multi = lookup(metrics, "multi") or {}
    base = c.get("baselines") or {}
    hover = inv.get("hover_detect_mm")
    rows: list[tuple[str, ...]] = [
        ("Contact point: mean error", _mm(inv.get("loc_mm_mean")),
         _mm(inv.get("contact_loc_mm_mean")), _best(inv.get("baseline_loc_mm_mean") or {}),
         _mm(inv.get("bound_loc_mm_mean"))),
    ]
    alone = inv.get("alone")
    if alone and alone.get("n_frames"):
        rows.append(("Contact point: mean error, no other finger above the skin",
                     _mm(alone.get("loc_mm_mean")), _mm(alone.get("contact_loc_mm_mean")),
                     _best(alone.get("baseline_loc_mm_mean") or {}),
                     _mm(alone.get("bound_loc_mm_mean"))))
    rows += [
        ("Force: mean absolute error", _n(inv.get("force_mae_n")), _n(c.get("force_mae_n")),
         _best_of(base, "force_mae_n", _n, True), _n(inv.get("bound_force_n_mean"))),
        ("Finger count (0, 1, 2) right", _pct(inv.get("count_accuracy")),
         _pct(multi.get("count_accuracy")),
         _best_of(multi.get("baselines") or {}, "count_accuracy", _pct, False), DASH),
        ("Hover detected up to (≥ 90 % of frames)", _mm(hover),
         _mm(c.get("hover_detect_mm")), _best_of(base, "hover_detect_mm", _mm, False), DASH),
    ]
    head: tuple[str, ...] = ("metric", "inversion (no training)", "ContactNet",
                             "strongest baseline", "bound (CRB)")
    return head, rows


def inversion_state_table(inv: Mapping[str, Any]) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """(header, rows) per inflation state: the point error of the inversion, ContactNet, the
    strongest baseline and the bound at the state's test frames; the inversion's and the
    bound's force; the inversion's count; its one-finger frames."""
    rows: list[tuple[str, ...]] = []
    for name, v in (inv.get("per_state") or {}).items():
        rows.append((
            str(name), _mm(v.get("loc_mm_mean")), _mm(v.get("contact_loc_mm_mean")),
            _best(v.get("baseline_loc_mm_mean") or {}), _mm(v.get("bound_loc_mm_mean")),
            _n(v.get("force_mae_n")), _n(v.get("bound_force_n_mean")),
            _pct(v.get("count_accuracy")), str(v.get("n_single_contact_frames", DASH)),
        ))
    head: tuple[str, ...] = ("state", "inversion", "ContactNet", "strongest baseline",
                             "bound (CRB)", "inversion force MAE", "force bound", "count right",
                             "one-finger frames")
    return head, rows


def force_line(inv: Mapping[str, Any], bound: Mapping[str, Any] | None) -> str | None:
    """One sentence on where force is observable: at the inversion's own frames (its force's
    standard error below the threshold) and, with the bound, on the faces near and away from
    the wires; None without the numbers."""
    share = inv.get("force_observable_share")
    thr = inv.get("force_observable_threshold_n") or 0.1
    if not isinstance(share, int | float):
        return None
    me = inv.get("model_error") or {}
    se = "the bound at the solution"
    if isinstance(me.get("r"), int | float) and isinstance(me.get("a_pf"), int | float):
        se += (f" with the field's model error, {1000 * me['a_pf']:.2g} fF and "
               f"{100 * me['r']:.2g} % of the signal, estimated from the validation fits' "
               f"residuals")
    text = (f"Force is observable (the fitted force's standard error, {se}, "
            f"below {thr:g} N) at {pct(share)} of the one-finger test frames"
            + (f"; there the inversion's force MAE is {_n(inv.get('force_mae_n_observable'))}"
               if isinstance(inv.get("force_mae_n_observable"), int | float) else ""))
    cover = inv.get("force_coverage") or {}
    if all(isinstance(cover.get(k), int | float) for k in ("1sigma", "2sigma")):
        text += (f"; {pct(cover['1sigma'])} of the force errors lie within one standard error "
                 f"and {pct(cover['2sigma'])} within two (a Gaussian's: 68 % and 95 %)")
    near = (bound or {}).get("force_observable_share_near_wires")
    away = (bound or {}).get("force_observable_share_away_from_wires")
    if isinstance(near, int | float) and isinstance(away, int | float):
        text += (f"; over the faces, the bound puts it within reach on {pct(near)} of the cells "
                 f"near a wire and on {pct(away)} of those away from every wire")
    return text + "."


#: the names of the contact choice's candidates in the report (others: ``baseline_name``)
CHOICE_NAMES = {"contactnet": "ContactNet", "inversion": "the inversion", "hybrid": "the hybrid"}


def _choice_name(key: Any) -> str:
    return CHOICE_NAMES.get(str(key), baseline_name(str(key)))


def choice_line(inv: Mapping[str, Any]) -> str | None:
    """One sentence on the contact model chosen for the states with a field (metrics.json's
    ``inversion.choice``): which, on how many validation frames and by which rule (the
    one-standard-error rule: the lowest validation error when the chosen one is not it), every
    candidate's validation point error, the chosen one's test error and its worst inflation
    state (where the step recorded one), and who answers the states without a field; None
    without a choice."""
    c = inv.get("choice")
    if not isinstance(c, Mapping) or not c.get("selected"):
        return None
    cands = c.get("candidates") or {}

    def err(name: str, split: str) -> Any:
        return ((cands.get(name) or {}).get(split) or {}).get("loc_mm_mean")

    chosen = str(c["selected"])
    others = ", ".join(f"{_choice_name(k)} {_mm(err(k, 'val'))}" for k in cands if k != chosen)
    ans = (c.get("answers") or {}).get("states_without_field") or {}
    share = ans.get("share_of_test_frames")
    best = c.get("best")
    rule = ("by the one-standard-error rule on the mean point error (the simplest candidate "
            "within one paired standard error of the lowest"
            + (f", {_choice_name(best)}'s" if best and best != chosen else "") + ")"
            if c.get("rule") == "one standard error (paired)"  # pipeline.contact_pick.RULE
            else "by the mean point error")
    worst = ((cands.get(chosen) or {}).get("test") or {}).get("worst_state")
    worst_text = (f", {_mm(worst[1])} in its worst inflation state ({worst[0]})"
                  if isinstance(worst, list | tuple) and len(worst) == 2 else "")
    text = (f"Contact model of the states with a field, chosen on {c.get('n_val_frames')} "
            f"validation frames {rule}: {_choice_name(chosen)}, "
            f"{_mm(err(chosen, 'val'))} ({others}); {_mm(err(chosen, 'test'))} on the test "
            f"frames{worst_text} (the hybrid is the inversion seeded with the learned model's "
            "guess).")
    if isinstance(share, int | float) and share > 0:
        text += (f" The test frames of states without a field ({_pct(share)}) can only be "
                 f"answered by the learned model ({_choice_name(ans.get('model'))}).")
    return text


def train_line(train: Mapping[str, Any] | None) -> str:
    """The inversion on the contact run's training trials, in one paragraph ("" for none)."""
    if not train or not train.get("n_frames"):
        return ""
    by = train.get("count_accuracy_by_true") or {}
    counts = " / ".join(_pct(by.get(k)) for k in ("0", "1", "2") if k in by)
    two = train.get("two_finger") or {}
    alone = train.get("alone") or {}
    bound = train.get("bound_alone_loc_mm_mean")
    text = (f"The training trials, which the inversion has not seen (it is not trained, and its "
            f"choices read the validation trials; the learned models and baselines were fitted "
            f"on them, so none is scored beside it here): {train['n_frames']} frames spread over "
            f"{train.get('n_trials')} trial(s), point error {_mm(train.get('loc_mm_mean'))} "
            f"(median {_mm(train.get('loc_mm_median'))})")
    if alone.get("n_frames"):
        text += (f"; with no other finger above the skin {_mm(alone.get('loc_mm_mean'))} over "
                 f"{alone['n_frames']} frames")
        if bound is not None:
            text += f", the bound {_mm(bound)} at those trials' frames"
    if counts:
        text += f"; counted right with 0 / 1 / 2 fingers on the skin {counts}"
    if two.get("n_frames"):
        text += (f"; {two['n_frames']} frames with two fingers from {two.get('n_trials')} "
                 f"trial(s), counted two on {_pct(two.get('count_accuracy'))}, each finger "
                 f"{_mm(two.get('loc_mm_mean'))} from its true point" + worst_state_text(two))
    return text + "."


def worst_state_text(two: Mapping[str, Any]) -> str:
    """"; lowest in STATE: P of N frames (T trial(s))" for the two-finger block's state with the
    lowest count accuracy ("" with fewer than two states scored: nothing to single out)."""
    by = {k: v for k, v in (two.get("by_state") or {}).items()
          if isinstance(v, Mapping) and isinstance(v.get("count_accuracy"), int | float)}
    if len(by) < 2:
        return ""
    name, worst = min(by.items(), key=lambda kv: kv[1]["count_accuracy"])
    return (f"; lowest in state {name}: {_pct(worst['count_accuracy'])} of "
            f"{worst.get('n_frames')} frames ({worst.get('n_trials')} trial(s))")


def _options_text(settings: Mapping[str, Any]) -> str:
    """What the fit assumed beyond the field: whose untouched readout, people's finger sizes,
    the press check (the step's settings; "" for a step made before they existed)."""
    out = []
    untouched = settings.get("untouched")
    if isinstance(untouched, Mapping) and untouched.get("source") == "auto":
        n = len(untouched.get("trials") or {})
        out.append(f" Each frame is compared with the skin's own untouched readout of its state "
                   f"(the mean of its no-contact trials outside the test split; {n} state(s) "
                   "have one, the others the field's).")
    sd = settings.get("finger_scale_sd")
    if isinstance(sd, int | float):
        out.append(f" Each finger's signal has an unknown scale (prior sd {sd:g}): people's "
                   "fingertips differ from the field's.")
    if settings.get("press_check"):
        out.append(" A finger fitted hovering is refitted pressing and kept so where that fits "
                   "about as well.")
    return "".join(out)


def _finger_text(finger: Any) -> str:
    """Whether each trial's frames pooled the person's finger (pulp, radius), and what the
    validation frames said of it ("" for a step made before the option, or with it off)."""
    if not isinstance(finger, Mapping) or "val_loc_mm_mean" not in finger and not finger.get("use"):
        return ""
    val = finger.get("val_loc_mm_mean") or {}
    force = finger.get("val_force_mae_n") or {}
    return (f" Each pressing finger's pulp modulus and radius are {'' if finger.get('use') else 'not '}"
            "fitted and pooled over its trial's frames, one person's"
            + (f", chosen on {finger.get('n_frames')} validation frames ({_mm(val.get('on'))} "
               f"and {_n(force.get('on'))} force MAE with it, {_mm(val.get('off'))} and "
               f"{_n(force.get('off'))} without)" if val else "") + ".")


def inversion_sections(metrics: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The report's items for metrics.json's ``inversion``; [] without it (or with no frame)."""
    inv = lookup(metrics, "inversion")
    if not isinstance(inv, Mapping) or not inv.get("n_frames"):
        return []
    s: list[tuple[str, Any]] = [("h2", "The physical inversion (no training)")]
    push = inv.get("push") or {}
    val = push.get("val_loc_mm_mean") or {}
    push_text = (
        f" The hand's push is {'a' if push.get('use') else 'not a'} nuisance of the fit"
        + (f", chosen on {push.get('n_frames')} validation frames ({_mm(val.get('on'))} with it, "
           f"{_mm(val.get('off'))} without)" if val else "")
        + "."
    )
    push_text += _options_text(inv.get("settings") or {}) + _finger_text(inv.get("finger"))
    n, n_all = inv.get("n_frames"), inv.get("n_frames_in_field_states")
    sub = (f" {n} of its {n_all} test frames in states with a field, evenly spread, were "
           "inverted." if isinstance(n_all, int) and isinstance(n, int) and n < n_all else "")
    s.append((
        "p",
        "Each test frame of the contact run is fitted"
        + ("" if (inv.get("finger") or {}).get("use") else ", alone,")
        + " through the twin's response field "
        "of its inflation state (docs/inversion.md): 0, 1 or 2 fingers, each finger's face, "
        "point, force or hover height, with drift as a nuisance, the count chosen by BIC. No "
        "training data. It is scored by ContactNet's metric function on the same test trials; "
        "ContactNet's and the baselines' point errors beside it are theirs on the same states."
        + sub + push_text,
    ))
    s.append(("table", inversion_table(metrics)))
    head, rows = inversion_state_table(inv)
    if rows:
        s.append(("p", "Per inflation state (point error mean; force MAE of the one-finger "
                       "frames):"))
        s.append(("table", (head, rows)))
    chosen = choice_line(inv)
    if chosen:
        s.append(("p", chosen))
    line = force_line(inv, lookup(metrics, "bound"))
    if line:
        s.append(("p", line))
    two = inv.get("two_finger") or {}
    if two.get("n_frames"):
        s.append(("p", f"Two fingers on the skin: {two['n_frames']} test frames of "
                       f"{two.get('n_trials')} trial(s), inverted apart from the spread above; "
                       f"counted two on {_pct(two.get('count_accuracy'))}, each finger "
                       f"{_mm(two.get('loc_mm_mean'))} from its true point after matching "
                       f"(median {_mm(two.get('loc_mm_median'))})"
                       + worst_state_text(two)
                       + ". The frames of one trial are one pair of fingers' moves: few trials "
                       "make this number coarse."))
    line = train_line(inv.get("train_trials"))
    if line:
        s.append(("p", line))
    med, p95 = inv.get("ms_per_frame_median"), inv.get("ms_per_frame_p95")
    if isinstance(med, int | float):
        pooled = (inv.get("finger") or {}).get("use")
        how = ("each frame cold, from the coarse search"
               + (", and again with its trial's pooled finger" if pooled else ""))
        s.append(("p", f"Time per frame of these fits on one core (this run, on its machine; "
                       f"{how}): median {med:.1f} ms"
                       + (f", 95th percentile {p95:.1f} ms" if isinstance(p95, int | float) else "")
                       + f". A live stream fits each frame from the previous frame's answer "
                       f"instead (target ≤ {LIVE_MS:g} ms a frame; its time: "
                       "benchmarks/bench_live.py, BENCHMARKS.md)."))
    missing = inv.get("frames_without_field") or {}
    if missing:
        s.append(("p", "Test frames in states without a response field (not inverted): "
                       + ", ".join(f"{k} ({v} frames)" for k, v in missing.items())
                       + f", {_pct(inv.get('share_without_field'))} of the test frames."))
    return s
