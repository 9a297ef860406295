"""The one-standard-error rule of the reproduction's contact model choice
(ectskin.pipeline.contact_pick.one_se_choice / choose), on per-frame errors given by hand: the
standard error is that of the paired difference to the best candidate (worked out by hand
below), the simplest candidate within it is chosen, and a candidate without per-frame errors
falls back to the lowest mean."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.pipeline import contact_pick as cp

ORDER = ["contactnet", "ridge", "knn", "inversion", "hybrid"]
#: the best candidate's errors on four frames: mean 5
HYBRID = np.array([2.0, 4.0, 6.0, 8.0])


def _means(per_frame):
    return {k: float(np.mean(v)) for k, v in per_frame.items()}


def test_a_simpler_candidate_within_one_paired_se_is_chosen():
    # inversion − hybrid = (1, −0.6, 1, −0.6): mean 0.2, deviations ±0.8, so
    # sd = √(4 · 0.64 / 3) = 0.92376, SE = sd / √4 = 0.46188 ≥ 0.2: within
    # ridge − hybrid = (3, 2, 3, 2): mean 2.5, deviations ±0.5, SE = √(1 / 3) / 2 = 0.28868: not
    frames = {"ridge": HYBRID + [3, 2, 3, 2], "inversion": HYBRID + [1, -0.6, 1, -0.6],
              "hybrid": HYBRID}
    order = ["ridge", "inversion", "hybrid"]
    c = cp.one_se_choice(_means(frames), order, frames)
    assert c["best"] == "hybrid" and c["rule"] == cp.RULE
    assert c["se"]["inversion"] == pytest.approx(math.sqrt(2.56 / 3) / 2, rel=1e-12)
    assert c["se"]["inversion"] == pytest.approx(0.46188, abs=1e-5)
    assert c["se"]["ridge"] == pytest.approx(math.sqrt(1 / 3) / 2, rel=1e-12)
    assert c["se"]["hybrid"] == 0.0
    assert c["within"] == {"ridge": False, "inversion": True, "hybrid": True}
    assert c["selected"] == "inversion"
    assert c["simplicity"] == ["ridge", "inversion", "hybrid"]
    assert "hybrid's 5.000: inversion 5.200" in c["why"] and "inversion 5.200" in c["why"]
    assert "+0.2000 (SE 0.4619)" in c["why"] and c["why"].startswith("the simplest candidate within one")
    assert cp.choose(_means(frames), order, frames) == (c["selected"], c["why"])


def test_the_best_is_kept_when_it_beats_the_simpler_ones_by_more_than_one_se():
    # inversion − hybrid = (1, 0.6, 1, 0.6): mean 0.8, SE = √(4 · 0.04 / 3) / 2 = 0.11547 < 0.8
    frames = {"ridge": HYBRID + [3, 2, 3, 2], "inversion": HYBRID + [1, 0.6, 1, 0.6],
              "hybrid": HYBRID}
    c = cp.one_se_choice(_means(frames), ["ridge", "inversion", "hybrid"], frames)
    assert c["se"]["inversion"] == pytest.approx(math.sqrt(0.16 / 3) / 2, rel=1e-12)
    assert c["within"] == {"ridge": False, "inversion": False, "hybrid": True}
    assert c["selected"] == "hybrid"
    assert c["why"].startswith(f"the lowest {cp.METRIC}: hybrid 5.000; no simpler candidate")
    assert "inversion +0.8000 (SE 0.1155)" in c["why"]


def test_the_se_is_of_the_paired_difference_not_of_the_two_means():
    # frames of very different difficulty, the same for both: the inversion is worse by about
    # 0.5 mm on every frame. Paired: differences (0.4, 0.6, ...), SE = √(6 · 0.01 / 5) / √6
    # = 0.044721 < 0.5, so the best stays. Unpaired (each mean's own SE, combined), or the best's
    # own SE as the rule is often stated for folds: several mm, and the inversion would be taken.
    hybrid = np.array([1.0, 2.0, 10.0, 20.0, 30.0, 40.0])
    inversion = hybrid + [0.4, 0.6, 0.4, 0.6, 0.4, 0.6]
    frames = {"inversion": inversion, "hybrid": hybrid}
    c = cp.one_se_choice(_means(frames), ["inversion", "hybrid"], frames)
    paired = math.sqrt(6 * 0.01 / 5) / math.sqrt(6)
    assert c["se"]["inversion"] == pytest.approx(paired, rel=1e-12)
    assert c["selected"] == "hybrid" and c["within"]["inversion"] is False
    n = hybrid.size
    unpaired = math.sqrt(hybrid.var(ddof=1) / n + inversion.var(ddof=1) / n)
    own = hybrid.std(ddof=1) / math.sqrt(n)
    gap = inversion.mean() - hybrid.mean()
    assert gap == pytest.approx(0.5) and unpaired > own > gap  # either would take the inversion


def test_the_simplicity_order_puts_the_runs_model_between_the_inversion_and_the_hybrid():
    base = np.array([1.0, 3.0, 2.0, 5.0])
    close = base + [0.3, -0.1, 0.3, -0.1]  # + 0.1, SE √(4 · 0.04 / 3) / 2 = 0.115: within
    # the run's model is best and the inversion within: the inversion (simpler)
    frames = {"contactnet": base, "inversion": close, "hybrid": close + 5}
    assert cp.choose(_means(frames), ORDER, frames)[0] == "inversion"
    # the run's model is best and only the hybrid within: the run's model (the hybrid is not
    # simpler); a run's model under another name takes the same place
    frames = {"contactnet": base, "inversion": base + 5, "hybrid": close}
    assert cp.choose(_means(frames), ORDER, frames)[0] == "contactnet"
    gbt = {"gbt" if k == "contactnet" else k: v for k, v in frames.items()}
    assert cp.choose(_means(gbt), ["gbt", "inversion", "hybrid"], gbt)[0] == "gbt"
    # the hybrid best and every other within: ridge, the simplest, then knn
    frames = {k: close if k != "hybrid" else base for k in ORDER}
    c = cp.one_se_choice(_means(frames), ORDER, frames)
    assert c["best"] == "hybrid" and c["selected"] == "ridge"
    assert c["simplicity"] == ["ridge", "knn", "inversion", "contactnet", "hybrid"]
    del frames["ridge"]
    assert cp.choose(_means(frames), [k for k in ORDER if k != "ridge"], frames)[0] == "knn"
    # equal errors on every frame: SE 0, within, so the simpler
    frames = {"contactnet": base, "knn": base.copy()}
    assert cp.choose(_means(frames), ORDER[:3], frames)[0] == "knn"


def test_candidates_without_per_frame_errors_fall_back_to_the_lowest_mean():
    errors = {"contactnet": 3.0, "ridge": 8.0, "knn": 6.0, "inversion": 1.0, "hybrid": 0.9}
    # no per-frame errors at all (the old callers): the lowest mean
    name, why = cp.choose(errors, ORDER)
    assert name == "hybrid" and why.startswith(f"the lowest {cp.METRIC}: hybrid 0.900")
    assert cp.one_se_choice(errors, ORDER)["rule"] == cp.PLAIN_RULE
    # the best has none: the lowest mean, though a simpler one is close
    frames = {"inversion": np.array([0.5, 1.5]), "hybrid": None}
    c = cp.one_se_choice(errors, ORDER, frames)
    assert c["selected"] == "hybrid" and c["rule"] == cp.PLAIN_RULE
    assert c["se"] == dict.fromkeys(ORDER)
    # a simpler one without them is never taken, however close; those with them are ruled on
    frames = {"inversion": np.array([1.0, 1.0]), "hybrid": np.array([0.5, 1.3]),
              "ridge": None}
    errors = {"ridge": 0.9, "inversion": 1.0, "hybrid": 0.9, "contactnet": math.nan}
    c = cp.one_se_choice(errors, ORDER, frames)
    assert c["best"] == "ridge"  # the lowest mean, ties to the earlier: no per-frame errors
    assert c["selected"] == "ridge" and c["rule"] == cp.PLAIN_RULE
    errors["ridge"] = 0.95
    c = cp.one_se_choice(errors, ORDER, frames)
    # inversion − hybrid = (0.5, −0.3): mean 0.1, SE = sd / √2 = 0.4: within
    assert c["best"] == "hybrid" and c["se"]["inversion"] == pytest.approx(0.4)
    assert c["selected"] == "inversion" and c["se"]["ridge"] is None
    assert c["within"]["ridge"] is None and c["within"]["contactnet"] is None
    # no finite error: the first candidate
    name, why = cp.choose({"contactnet": math.nan, "inversion": math.nan}, ORDER)
    assert name == "contactnet" and why.startswith("no validation frame")


def test_errors_that_are_not_of_the_same_frames_are_refused():
    good = {"inversion": np.array([1.0, 2.0]), "hybrid": np.array([0.5, 1.0])}
    with pytest.raises(EctskinError, match="not the same frames"):
        cp.one_se_choice({"inversion": 1.5, "hybrid": 0.75}, ORDER,
                         {**good, "inversion": np.array([1.0, 2.0, 1.5])})
    with pytest.raises(EctskinError, match="do not average to its validation error"):
        cp.one_se_choice({"inversion": 1.4, "hybrid": 0.75}, ORDER, good)
    with pytest.raises(EctskinError, match="no candidates"):
        cp.one_se_choice({}, [], None)
    with pytest.raises(EctskinError, match="paired_se"):
        cp.paired_se(np.ones(3), np.ones(2))
    assert cp.paired_se(np.ones(1), np.zeros(1)) is None  # one frame: no standard error
    # with one frame only the best can be within
    one = {"inversion": np.array([1.0]), "hybrid": np.array([0.9])}
    assert cp.choose({"inversion": 1.0, "hybrid": 0.9}, ORDER, one)[0] == "hybrid"


def test_the_report_line_names_the_rule_and_the_lowest_when_it_was_not_taken():
    from ectskin.report.inversion import choice_line

    cands = {k: {"val": {"loc_mm_mean": v}, "test": {"loc_mm_mean": v + 0.1}}
             for k, v in (("contactnet", 1.31), ("inversion", 1.25), ("hybrid", 1.22))}
    c = {"selected": "inversion", "best": "hybrid", "rule": cp.RULE, "n_val_frames": 480,
         "candidates": cands}
    line = choice_line({"choice": c})
    assert line is not None
    assert ("chosen on 480 validation frames by the one-standard-error rule on the mean point "
            "error (the simplest candidate within one paired standard error of the lowest, the "
            "hybrid's): the inversion, 1.25 mm (ContactNet 1.31 mm, the hybrid 1.22 mm); "
            "1.35 mm on the test frames") in line
    line = choice_line({"choice": {**c, "selected": "hybrid"}})
    assert line is not None and "of the lowest): the hybrid, 1.22 mm" in line
    old = choice_line({"choice": {k: v for k, v in c.items() if k not in ("rule", "best")}})
    assert old is not None and "validation frames by the mean point error: the inversion" in old
    # the chosen one's worst inflation state, where the step recorded it
    cands["inversion"]["test"]["worst_state"] = ["0/0/0 ml", 2.86]
    line = choice_line({"choice": c})
    assert line is not None
    assert "1.35 mm on the test frames, 2.86 mm in its worst inflation state (0/0/0 ml)" in line
