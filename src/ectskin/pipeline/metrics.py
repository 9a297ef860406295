"""The reproduction's ``metrics.json``: the per-run metrics combined, and the report's figures.

:func:`combine_metrics` builds the dict that :mod:`ectskin.report` renders (its keys are listed
there): the paper runs' metrics under ``touch`` and ``track``; the robust TouchMLP under
``touch.robust``, with ``recipe_description``, its training recipe in words; the ablations under
``track.ablations``; the contact run's blocks (:func:`contact_blocks`), with the force error
where the bound says force is observable and where not (:func:`force_split_keys`); the physical limit under
``bound`` (:func:`bound_block`, from the bound step's bound.json); the training-free inversion
under ``inversion`` (:func:`inversion_block`, from the inversion step's metrics); then the data, the protocol,
the step timings, the reused steps and the machine.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError
from ectskin.io import list_trials
from ectskin.learn.metrics.contact import FORCE_SPLIT_PARTS
from ectskin.learn.profiles import describe_recipe
from ectskin.pipeline.config import ABLATIONS
from ectskin.pipeline.runner import StepRunner
from ectskin.report import machine_info
from ectskin.twin import Protocol
from ectskin.viz import figure_file

METRICS_FORMAT = "ectskin.metrics"

#: keys of the robust run's touch metrics copied into metrics.json under ``touch.robust``
ROBUST_KEYS = (
    "accuracy",
    "n_test_frames",
    "n_misclassified",
    "misclassified",
    "n_misclassified_adjacent",
    "all_adjacent",
    "confusions",
    "per_class_accuracy",
    "per_trial",
    "worst_trial",
    "training",
    "split",
    "reference",
    "baselines",  # fitted on the robust run's own calibrated inputs (its Eq. 2 reference)
)
#: keys of an ablation run's track metrics copied under ``track.ablations.<key>``
ABLATION_KEYS = (
    "ad_mm_mean",
    "ad_mm_std",
    "ad_mm_median",
    "n_test_samples",
    "window",
    "prior",
    "per_marker",
    "worst_trajectory",
    "training",
    "examples",
)

#: figures copied into OUT_DIR/figures and shown in the report: (run, figure stem, caption, stem
#: of the copy); the files are ``<stem>.<format>`` in the reproduction's figure format
REPORT_FIGURES = (
    (
        "touch",
        "fig7_confusion",
        "Fig. 7: touch confusion map of the test set (TouchMLP)",
        "fig7_confusion",
    ),
    (
        "touch_robust",
        "fig7_confusion",
        "Fig. 7, robust recipe (ours): touch confusion map of the same test set (TouchMLP)",
        "fig7_confusion_robust",
    ),
    (
        "track",
        "fig9_tracking",
        "Fig. 9: tracking examples, estimated (red) vs true (blue) markers (C2DT)",
        "fig9_tracking",
    ),
    (
        "track",
        "fig10_trajectory",
        "Fig. 10: one marker's trajectory over a test trial (C2DT)",
        "fig10_trajectory",
    ),
    ("touch", "learning_curves", "TouchMLP training and validation loss", "touch_learning_curves"),
    (
        "touch_robust",
        "learning_curves",
        "TouchMLP, robust recipe: training (augmented) and validation loss",
        "touch_robust_learning_curves",
    ),
    ("track", "learning_curves", "C2DT training and validation loss", "track_learning_curves"),
    (
        "contact",
        "contact_error_map",
        "Contact localisation error over each face (ContactNet, test trials of the contact experiment)",
        "contact_error_map",
    ),
    (
        "contact",
        "contact_force",
        "Contact force, predicted against true (ContactNet)",
        "contact_force",
    ),
    (
        "contact",
        "contact_hover",
        "Hover detection rate against the finger's height (ContactNet)",
        "contact_hover",
    ),
)
#: contact metrics copied to metrics.json's ``contact`` (and, for each baseline, beside them)
CONTACT_KEYS = (
    "loc_mm_mean",
    "loc_mm_median",
    "loc_mm_p90",
    "face_accuracy",
    "force_mae_n",
    "force_rel",
    "force_coverage_1sigma",
    "force_coverage_2sigma",
    "force_sigma_n_median",
    "hover_detect_mm",
    "contact_accuracy",
    "n_single_contact_frames",
)
#: the force split's keys (:func:`ectskin.learn.metrics.contact.force_split`) copied into
#: ``contact`` and each of its baselines, as key in the split → key in metrics.json
FORCE_SPLIT_KEYS = {
    **{f"force_mae_n_{p}": f"force_mae_n_{p}" for p in FORCE_SPLIT_PARTS},
    **{f"share_{p}": f"force_share_{p}" for p in FORCE_SPLIT_PARTS},
    **{f"n_frames_{p}": f"force_n_frames_{p}" for p in FORCE_SPLIT_PARTS},
    **{f"force_coverage_{k}sigma_{p}": f"force_coverage_{k}sigma_{p}"
       for p in FORCE_SPLIT_PARTS for k in (1, 2)},
}
#: two-finger metrics copied to ``multi``
MULTI_KEYS = (
    "count_accuracy",
    "count_accuracy_by_true",
    "count_confusion",
    "loc_mm_mean",
    "loc_mm_median",
    "loc_mm_p90",
    "n_fingers",
    "n_two_finger_frames",
)


def contact_blocks(run: Mapping[str, Any]) -> dict[str, Any]:
    """``contact`` and ``multi`` of metrics.json from the contact run's metrics.json."""
    c = run.get("contact", {})
    baselines = c.get("baselines") or {}
    contact = {k: c.get(k) for k in CONTACT_KEYS}
    contact.update(
        per_face=c.get("per_face"),
        per_state=c.get("per_state"),
        hover=c.get("hover"),
        force=c.get("force"),
        window=c.get("window"),
        arch=c.get("arch"),
        training=c.get("training"),
        split=c.get("split"),
        by_other_finger=c.get("by_other_finger"),
        baselines={
            b: {
                **{k: v.get(k) for k in CONTACT_KEYS},
                "per_state": v.get("per_state"),
                "by_other_finger": v.get("by_other_finger"),
            }
            for b, v in baselines.items()
        },
    )
    multi_of = lambda m: {k: (m.get("multi") or {}).get(k) for k in MULTI_KEYS}  # noqa: E731
    multi = multi_of(c)
    multi["baselines"] = {b: multi_of(v) for b, v in baselines.items()}
    return {"contact": contact, "multi": multi}


def force_split_keys(contact: dict[str, Any], split: Mapping[str, Any] | None) -> None:
    """Put the force split of the bound step (:func:`ectskin.pipeline.bound.contact_force_split`:
    {"model", "threshold_n", "models": {name: split}}) into metrics.json's ``contact`` block:
    the answering model's :data:`FORCE_SPLIT_KEYS` on top, each baseline's beside its other
    numbers, and ``force_split`` (the threshold, the bound's case, every model's whole split,
    the mean bound in each part)."""
    if not split:
        return
    models = split.get("models") or {}
    own = models.get(split.get("model")) or {}
    contact.update({new: own.get(old) for old, new in FORCE_SPLIT_KEYS.items()})
    for name, b in (contact.get("baselines") or {}).items():
        if name in models:
            b.update({new: models[name].get(old) for old, new in FORCE_SPLIT_KEYS.items()})
    contact["force_split"] = {
        "threshold_n": split.get("threshold_n"),
        "case": split.get("case"),
        "model": split.get("model"),
        "models": dict(models),
    }


def handling_block(off_run: Mapping[str, Any]) -> dict[str, Any]:
    """``contact.handling_off`` of metrics.json: the contact metrics (and the baselines') of the
    same test trials with the experimenter's hand off, with the two-finger count accuracy."""
    blocks = contact_blocks(off_run)
    off = {k: v for k, v in blocks["contact"].items() if k in CONTACT_KEYS or k == "baselines"}
    off["per_state"] = blocks["contact"].get("per_state")
    off["count_accuracy"] = blocks["multi"].get("count_accuracy")
    for name, b in off["baselines"].items():
        b["count_accuracy"] = blocks["multi"]["baselines"].get(name, {}).get("count_accuracy")
    return off


def combine_metrics(
    results: Mapping[str, dict[str, Any]],
    runner: StepRunner,
    *,
    profile: str,
    seed: int,
    protocol: Protocol | None,
    data_settings: Mapping[str, Any],
    data_path: Path,
    contact: Mapping[str, Any] | None = None,
    bound: Mapping[str, Any] | None = None,
    inversion: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The OUT_DIR/metrics.json dict from ``results`` ({run: its metrics.json}), the contact
    run's metrics.json (``contact``, None when it did not run), the bound step's bound.json
    (``bound``) and the inversion step's metrics (``inversion``; each None when it did not
    run)."""
    m: dict[str, Any] = {
        "format": METRICS_FORMAT,
        "version": 1,
        "profile": profile,
        "seed": seed,
        "created_utc": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
    }
    if "touch" in results:
        m["touch"] = dict(results["touch"].get("touch", {}))
        if "touch_robust" in results:
            r = results["touch_robust"].get("touch", {})
            robust = {k: r[k] for k in ROBUST_KEYS if k in r}
            # the report's words for the recipe (the report itself reads no training code)
            robust["recipe_description"] = describe_recipe((r.get("training") or {}).get("recipe"))
            m["touch"]["robust"] = robust
    if "track" in results:
        m["track"] = dict(results["track"].get("track", {}))
        abl = {}
        for key, name in ABLATIONS.items():
            if name in results:
                r = results[name].get("track", {})
                abl[key] = {k: r.get(k) for k in ABLATION_KEYS if k in r}
        if abl:
            m["track"]["ablations"] = abl
    if contact is not None:
        m.update(contact_blocks(contact))
        if bound is not None:
            force_split_keys(m["contact"], bound.get("force_split"))
    if bound is not None:
        m["bound"] = bound_block(bound, m.get("contact"))
    if inversion is not None:
        m["inversion"] = inversion_block(inversion, m.get("contact"), m.get("bound"))
    try:
        n_trials = len(list_trials(data_path))
    except EctskinError:
        n_trials = None
    m["data"] = {"file": data_path.name, "source": data_settings.get("source"), "trials": n_trials}
    if protocol is not None:
        m["protocol"] = protocol.to_dict()
    m["timings_s"] = dict(runner.timings)
    m["reused"] = list(runner.reused)
    m["machine"] = machine_info()
    return m


#: the keys of a reduction of bounds copied into metrics.json's ``bound`` blocks
BOUND_KEYS = (
    "loc_mm_mean",
    "loc_mm_median",
    "loc_mm_p95",
    "force_n_mean",
    "force_n_median",
    "force_observable_share",
    "force_observable_share_near_wires",
    "force_observable_share_away_from_wires",
    "position_resolved_share",
    "force_resolved_share",
    "n_points",
)


def _pooled(parts: list[Mapping[str, Any]]) -> dict[str, Any]:
    """Reductions of parts (each over its own points) pooled: the means weighted by each part's
    resolved points, the shares by its points; medians and p95 cannot be pooled and are left
    out."""
    n = [p.get("n_points") or 0 for p in parts]
    out: dict[str, Any] = {"n_points": int(sum(n))}
    for key, weight in (
        ("loc_mm_mean", "position_resolved_share"),
        ("force_n_mean", "force_resolved_share"),
        ("force_observable_share", None),
        ("position_resolved_share", None),
        ("force_resolved_share", None),
    ):
        num = den = 0.0
        for p, k in zip(parts, n):
            w = k * (p.get(weight) or 0.0) if weight else k
            if isinstance(p.get(key), int | float) and w > 0:
                num += w * p[key]
                den += w
        out[key] = num / den if den > 0 else None
    return out


def bound_block(bound: Mapping[str, Any], contact: Mapping[str, Any] | None) -> dict[str, Any]:
    """metrics.json's ``bound`` from the bound step's bound.json (``docs/bound.md``, "In
    metrics.json"): the headline case's reductions over every map cell, per face, per state (with
    the bound at the test frames' true points and ContactNet's error of the same state beside
    it), every case pooled, and the settings; ``contact``: metrics.json's ``contact`` or None."""
    case = bound.get("headline_case") or "all"
    settings = bound.get("settings") or {}
    per_face_parts: dict[str, list[Mapping[str, Any]]] = {}
    per_state: dict[str, Any] = {}
    test = bound.get("test") or {}
    test_states = test.get("per_state") or {}
    model_states = (contact or {}).get("per_state") or {}
    base = (contact or {}).get("baselines") or {}
    for st in bound.get("states") or []:
        name = "/".join(f"{float(v):g}" for v in st["inflation_ml"]) + " ml"
        faces = {
            f: {k: (e["contact"][case].get("reduction") or {}).get(k) for k in BOUND_KEYS}
            for f, e in (st.get("faces") or {}).items()
        }
        for f, r in faces.items():
            per_face_parts.setdefault(f, []).append(r)
        entry: dict[str, Any] = {**_pooled(list(faces.values())), "per_face": faces}
        entry["test"] = test_states.get(name)
        entry["contact_loc_mm_mean"] = (model_states.get(name) or {}).get("loc_mm_mean")
        entry["baseline_loc_mm_mean"] = {
            b: ((v.get("per_state") or {}).get(name) or {}).get("loc_mm_mean")
            for b, v in base.items()
        }
        per_state[name] = entry
    top = (bound.get("summary") or {}).get("contact", {})
    head = top.get(case) or {}
    return {
        "case": case,
        **{k: head.get(k) for k in BOUND_KEYS},
        "per_face": {f: _pooled(parts) for f, parts in per_face_parts.items()},
        "per_state": per_state,
        "cases": {c: {k: v.get(k) for k in BOUND_KEYS} for c, v in top.items()},
        "test": {**(test.get("pooled") or {}), "states_without_field": test.get("states_without_field")},
        "test_alone": (bound.get("test_alone") or {}).get("pooled"),
        "train_alone": (bound.get("train_alone") or {}).get("pooled"),
        "settings": {k: settings.get(k) for k in (
            "source", "faces", "spacing_mm", "force_n", "nuisances", "prior_sd",
            "force_threshold_n", "near_wire_mm", "position", "push_columns")},
        "nuisance_columns": bound.get("nuisance_columns"),
        "timing_s": (bound.get("timing") or {}).get("total_s"),
    }


#: the inversion's metrics copied into metrics.json's ``inversion`` (as ContactNet's in
#: ``contact``)
INVERSION_KEYS = CONTACT_KEYS + ("count_accuracy", "sigma_mm_median", "converged_share",
                                 "n_frames", "n_frames_in_field_states", "n_frames_without_field",
                                 "share_without_field", "frames_without_field", "n_test_trials")
#: the inversion's per-state metrics copied into ``inversion.per_state``
INVERSION_STATE_KEYS = ("loc_mm_mean", "loc_mm_median", "loc_mm_p90", "face_accuracy",
                        "force_mae_n", "count_accuracy", "hover_detect_mm",
                        "n_single_contact_frames", "n_frames")


def same_states(per_state: Mapping[str, Any] | None, states: list[str],
                key: str = "loc_mm_mean") -> float | None:
    """The mean of ``key`` over the frames of ``states``, from per-state means weighted by their
    ``n_frames`` (a contact report's ``per_state``, whose ``n_frames`` are its one-finger
    frames): a model's error on the states the inversion covers. None when a state lacks it."""
    num = den = 0.0
    for name in states:
        v = (per_state or {}).get(name) or {}
        x, n = v.get(key), v.get("n_frames")
        if not isinstance(x, int | float) or not isinstance(n, int):
            return None
        num += x * n
        den += n
    return num / den if den else None


def beside(contact: Mapping[str, Any] | None, inversion: Mapping[str, Any]) -> dict[str, Any]:
    """ContactNet's (``contact``: metrics.json's ``contact`` or the run's ``contact`` block) and
    each baseline's mean point error over the inflation states in which the inversion scored a
    one-finger frame: {"loc_mm_mean", "baselines": {name: mm}, "states"}."""
    c = contact or {}
    states = [s for s, v in (inversion.get("per_state") or {}).items()
              if (v.get("n_single_contact_frames") or 0) > 0]
    return {
        "loc_mm_mean": same_states(c.get("per_state"), states),
        "baselines": {b: same_states(v.get("per_state"), states)
                      for b, v in (c.get("baselines") or {}).items()},
        "states": states,
    }


def alone_beside(contact: Mapping[str, Any] | None, inversion: Mapping[str, Any],
                 bound: Mapping[str, Any] | None = None) -> dict[str, Any] | None:
    """The one-finger point error with no other finger above the skin (``by_other_finger``'s
    ``alone``): the inversion's, and ContactNet's (``contact``) and each baseline's over the
    states in which the inversion scored such a frame (:func:`same_states`), and the bound at
    the test frames without another finger (metrics.json's ``bound.test_alone``, ``bound``);
    None without the inversion's split."""
    part = (inversion.get("by_other_finger") or {}).get("alone")
    if not part:
        return None
    states = [s for s, v in (part.get("per_state") or {}).items() if (v.get("n_frames") or 0)]

    def alone(block: Mapping[str, Any] | None) -> Mapping[str, Any]:
        return ((block or {}).get("by_other_finger") or {}).get("alone") or {}

    c = contact or {}
    return {
        "loc_mm_mean": part.get("loc_mm_mean"), "n_frames": part.get("n_frames"),
        "contact_loc_mm_mean": same_states(alone(c).get("per_state"), states),
        "baseline_loc_mm_mean": {b: same_states(alone(v).get("per_state"), states)
                                 for b, v in (c.get("baselines") or {}).items()},
        "bound_loc_mm_mean": ((bound or {}).get("test_alone") or {}).get("loc_mm_mean"),
        "states": states,
    }


def _train_trials(block: Mapping[str, Any] | None, bound: Mapping[str, Any] | None
                  ) -> dict[str, Any] | None:
    """The step's ``train_trials`` without the two-finger frames' per-trial list, and the bound
    at the training frames with one finger alone (metrics.json's ``bound.train_alone``) beside
    its point error there (``bound_alone_loc_mm_mean``; None where the bound step made none)."""
    if not block:
        return None
    return {**block, "two_finger": _without_trials(block.get("two_finger")),
            "bound_alone_loc_mm_mean": ((bound or {}).get("train_alone") or {}).get("loc_mm_mean")}


def _without_trials(two: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """A two-finger block without its per-trial list (the step's file keeps it); None for none."""
    return {k: v for k, v in two.items() if k != "count_accuracy_by_trial"} if two else None


def inversion_block(inv: Mapping[str, Any], contact: Mapping[str, Any] | None,
                    bound: Mapping[str, Any] | None) -> dict[str, Any]:
    """metrics.json's ``inversion`` from the inversion step's metrics (``docs/reproduce.md``):
    its contact metrics (:data:`INVERSION_KEYS`), the count by true count, the two-finger frames
    scored apart (``two_finger``, without its per-trial list), the same on the contact run's
    training trials (``train_trials``: the inversion is not trained), force where its
    standard error says it is observable, the share of force errors within 1 and 2 standard
    errors (``force_coverage``) and the model error those carry (``model_error``), the time per
    frame, and per state its numbers beside ContactNet's, the baselines' and the bound's at the
    same state's test frames, and the contact model choice of the field states (``choice``,
    :mod:`ectskin.pipeline.contact_pick`; None where the step made none); ``contact`` and
    ``bound``: metrics.json's blocks (or None)."""
    timing = inv.get("timing") or {}
    fo = inv.get("force_observable") or {}
    near = beside(contact, inv)
    bound_states = (bound or {}).get("per_state") or {}
    per_state = {}
    for name, v in (inv.get("per_state") or {}).items():
        b = (bound_states.get(name) or {}).get("test") or {}
        per_state[name] = {
            **{k: v.get(k) for k in INVERSION_STATE_KEYS},
            "contact_loc_mm_mean": same_states((contact or {}).get("per_state"), [name]),
            "baseline_loc_mm_mean": {
                k: same_states(x.get("per_state"), [name])
                for k, x in ((contact or {}).get("baselines") or {}).items()},
            "bound_loc_mm_mean": b.get("loc_mm_mean"),
            "bound_force_n_mean": b.get("force_n_mean"),
        }
    btest = (bound or {}).get("test") or {}
    return {
        **{k: inv.get(k) for k in INVERSION_KEYS},
        "count_accuracy_by_true": (inv.get("multi") or {}).get("count_accuracy_by_true"),
        "by_other_finger": inv.get("by_other_finger"),
        "alone": alone_beside(contact, inv, bound),
        "two_finger": _without_trials(inv.get("two_finger")),
        "train_trials": _train_trials(inv.get("train_trials"), bound),
        "force_mae_n_observable": fo.get("force_mae_n"),
        "force_observable_share": fo.get("share"),
        "force_observable_threshold_n": fo.get("threshold_n"),
        "force_coverage": {k: (inv.get("force") or {}).get(f"force_coverage_{k}")
                           for k in ("1sigma", "2sigma")},
        "model_error": inv.get("model_error"),
        "ms_per_frame_median": timing.get("ms_per_frame_median"),
        "ms_per_frame_p95": timing.get("ms_per_frame_p95"),
        "per_state": per_state,
        "contact_loc_mm_mean": near["loc_mm_mean"],
        "baseline_loc_mm_mean": near["baselines"],
        "bound_loc_mm_mean": btest.get("loc_mm_mean"),
        "bound_force_n_mean": btest.get("force_n_mean"),
        "push": inv.get("push"),
        "finger": inv.get("finger"),
        "choice": inv.get("choice"),
        "settings": inv.get("settings"),
        "timing_s": {k: timing.get(k) for k in ("total_s", "invert_s", "push_basis_s")},
    }


#: the bound step's figures (file stem in OUT_DIR/bound, caption), copied by :func:`copy_figures`
BOUND_FIGURES = (
    ("bound", "The physical limit: Cramér–Rao bound maps of the finger's point and force per "
              "inflation state (every nuisance at its prior)"),
    ("bound_vs_error", "ContactNet's localisation error beside the bound (the same log scale)"),
)
#: the inversion step's figures (file stem in OUT_DIR/inversion, caption), copied likewise
INVERSION_FIGURES = (
    ("error_vs_bound", "The inversion's localisation error beside the bound (the same log scale)"),
    ("force_sigma", "Contact force of the inversion against the true force, ±1σ its standard "
                    "error (observable: that standard error below 0.1 N)"),
    ("two_fingers", "Two fingers on the skin as the inversion reads them (test frames evenly "
                    "spread over those with two fingers)"),
)


def copy_figures(out: Path, runs: tuple[str, ...], figure_format: str = "png") -> dict[str, str]:
    """Copy the report's figures of ``runs`` (files in ``figure_format``) into OUT_DIR/figures;
    {caption: path relative to OUT_DIR}."""
    fig_dir = out / "figures"
    fig_dir.mkdir(exist_ok=True)
    figures: dict[str, str] = {}
    for run, stem, caption, copy_stem in REPORT_FIGURES:
        src = out / "runs" / run / figure_file(stem, figure_format)
        if run in runs and src.is_file():
            dst = fig_dir / figure_file(copy_stem, figure_format)
            shutil.copyfile(src, dst)
            figures[caption] = dst.relative_to(out).as_posix()
    for folder, items in (("bound", BOUND_FIGURES), ("inversion", INVERSION_FIGURES)):
        for stem, caption in items:
            src = out / folder / figure_file(stem, figure_format)
            if src.is_file():
                dst = fig_dir / (src.name if folder == "bound" else f"{folder}_{src.name}")
                shutil.copyfile(src, dst)
                figures[caption] = dst.relative_to(out).as_posix()
    return figures
