"""Inflation-referenced calibration (ectskin.io.inflation_reference, the "state" and "inflation"
references of ectskin.io.calibration.touch_reference and ectskin.learn.data.touch).

Independent references: hand-computed Eq. 2 against a state's rest mean; an analytic quadratic
c_0(p) that the degree-2 model must reproduce exactly, also at volumes it was not fitted on.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import Recording, Trial
from ectskin.io.calibration import REFERENCE_OPTIONS, touch_reference
from ectskin.io.inflation_reference import InflationModel, monomials, state_reference
from ectskin.layout import default_layout
from ectskin.learn.data.touch import reference_doc, touch_dataset
from ectskin.learn.profiles import PROFILE_REFERENCE, REFERENCES, TrainConfig

LAYOUT = default_layout()
P = LAYOUT.n_pairs


def _trial(name, values, inflation, region=0, n=4, kind=None):
    values = np.broadcast_to(np.asarray(values, np.float64), (n, P)).copy()
    kind = kind or ("touch" if region else "no_contact")
    return Trial(
        name,
        values,
        np.arange(n) / 30,
        np.full(n, region),
        inflation=inflation,
        region=region,
        meta={"kind": kind},
    )


def test_state_reference_is_eq2_against_the_states_own_rest_mean():
    """Two states; state B has two no-contact trials of 2 and 6 frames: its reference is the
    mean over their 8 frames, (2·1.5 + 6·2.5)/8 = 2.25 pF (a mean of the two trial means would
    give 2.0). Touch frames of 2.7 pF in state B calibrate to (2.7 − 2.25)/2.25 = 0.2, those of
    1.1 pF in state A (rest 1.0 pF) to 0.1. Catches: one reference for all states (the 0-ml
    rest: state B's touch would read 1.7), the wrong state, a per-trial mean of means, Eq. 2
    with c_t in the denominator."""
    rec = Recording(
        LAYOUT,
        [
            _trial("a_rest", 1.0, (0.0, 0.0)),
            _trial("a_touch", 1.1, (0.0, 0.0), region=3),
            _trial("b_rest1", 1.5, (10.0, 0.0), n=2),
            _trial("b_touch", 2.7, (10.0, 0.0), region=12),
            _trial("b_rest2", 2.5, (10.0, 0.0), n=6),
        ],
        30.0,
    )
    refs = touch_reference(rec, reference="state")
    np.testing.assert_allclose(refs["b_touch"], 2.25)
    np.testing.assert_allclose(refs["b_rest1"], 2.25)
    np.testing.assert_allclose(refs["a_touch"], 1.0)
    ds = touch_dataset(rec, reference="state")
    x = {n: ds.x[ds.group == g] for g, n in enumerate(ds.group_names)}
    np.testing.assert_allclose(x["b_touch"], 0.2, rtol=1e-6)
    np.testing.assert_allclose(x["a_touch"], 0.1, rtol=1e-6)
    np.testing.assert_allclose(x["b_rest1"], (1.5 - 2.25) / 2.25, rtol=1e-6)
    assert ds.reference == {"mode": "state"}
    # the paper's reference, for contrast: the 0-ml rest for every trial
    np.testing.assert_allclose(touch_dataset(rec, reference="rest").x[ds.group == 3], 1.7)


def test_state_offset_subtracts_the_states_rest_and_divides_by_the_rest_states():
    """The robust profile's reference: c = (c_t − c_0(p)) / c_0(0). The recording of the test
    above: state B's touch (2.7 pF, its rest mean 2.25 pF, the 0-ml rest 1.0 pF) reads
    (2.7 − 2.25) / 1.0 = 0.45, state A's (rest 1.0 pF) (1.1 − 1.0) / 1.0 = 0.1 (= "state",
    its own rest is the 0-ml rest). Catches dividing by the state's own rest (0.2, "state"),
    subtracting the 0-ml rest (1.7, "rest"), and the profile's reference changing unnoticed."""
    rec = Recording(
        LAYOUT,
        [
            _trial("a_rest", 1.0, (0.0, 0.0)),
            _trial("a_touch", 1.1, (0.0, 0.0), region=3),
            _trial("b_rest1", 1.5, (10.0, 0.0), n=2),
            _trial("b_touch", 2.7, (10.0, 0.0), region=12),
            _trial("b_rest2", 2.5, (10.0, 0.0), n=6),
        ],
        30.0,
    )
    ds = touch_dataset(rec, reference="state-offset")
    x = {n: ds.x[ds.group == g] for g, n in enumerate(ds.group_names)}
    np.testing.assert_allclose(x["b_touch"], 0.45, rtol=1e-6)
    np.testing.assert_allclose(x["a_touch"], 0.1, rtol=1e-6)
    np.testing.assert_allclose(x["b_rest2"], 2.5 - 2.25, rtol=1e-6)
    assert ds.reference == {"mode": "state-offset"}
    assert PROFILE_REFERENCE["robust"] == "state-offset"


def test_state_reference_refuses_a_state_without_a_no_contact_trial():
    """The error names the state and a trial of it (catches a silent fallback to the rest)."""
    rec = Recording(
        LAYOUT,
        [
            _trial("a_rest", 1.0, (0.0, 0.0)),
            _trial("b_touch", 2.0, (20.0, 10.0), region=4),
        ],
        30.0,
    )
    with pytest.raises(EctskinError, match=r"trial 'b_touch'.*\(20, 10\) ml has no no-contact"):
        touch_reference(rec, reference="state")
    with pytest.raises(EctskinError, match=r"\(20, 10\) ml has no no-contact"):
        touch_dataset(rec, reference="state")


def test_a_recording_without_inflation_values():
    """"inflation" needs the chamber volumes: an error naming the recording. "state" takes a
    non-inflatable skin (no trial has inflation values) as one state, its no-contact trials the
    reference (= "rest"). Trials with volumes of different lengths are an error naming both."""
    rec = Recording(
        LAYOUT,
        [_trial("rest", 2.0, ()), _trial("touch", 2.5, (), region=1)],
        30.0,
        source="flat.h5",
    )
    with pytest.raises(EctskinError, match=r"flat.h5: has no inflation values"):
        touch_dataset(rec, reference="inflation")
    np.testing.assert_allclose(touch_dataset(rec, reference="state").x[4:], 0.25, rtol=1e-6)
    mixed = Recording(
        LAYOUT, [_trial("rest", 2.0, (0.0,)), _trial("touch", 2.5, (), region=1)], 30.0
    )
    with pytest.raises(EctskinError, match=r"trial 'touch': inflation \[\] has 0 chamber"):
        touch_reference(mixed, reference="state")


# --------------------------------------------------------------------------- the model
RNG = np.random.default_rng(5)
BASE = RNG.uniform(0.5, 2.0, P)
LIN = RNG.uniform(-0.3, 0.3, (3, P))
QUAD = RNG.uniform(-0.1, 0.1, (3, 3, P))


def c0_true(p) -> np.ndarray:
    """An analytic quadratic rest readout, pF: base (1 + a·q + qᵀ B q), q = p / 20 ml, with
    cross terms (B not diagonal)."""
    q = np.asarray(p, np.float64) / 20.0
    return BASE * (1 + q @ LIN + np.einsum("i,j,ijp->p", q, q, QUAD))


def quadratic_recording(levels=(0.0, 10.0, 20.0), *, touch=True, rest=True, seed=0) -> Recording:
    """Per state (levels³) a no-contact trial at c0_true(p) and a touch trial: the readout
    c0_true(p) × (1 + 0.05 pattern[region]), region by state."""
    rng = np.random.default_rng(seed)
    patterns = rng.uniform(0.2, 1.0, (19, P))
    trials = []
    for k, p in enumerate(itertools.product(levels, repeat=3)):
        c0 = c0_true(p)
        if rest:
            trials.append(_trial(f"s{k}_rest", c0, p, n=6))
        if touch:
            r = 1 + (k % 6)
            trials.append(_trial(f"s{k}_touch", c0 * (1 + 0.05 * patterns[r]), p, region=r, n=6))
    return Recording(LAYOUT, trials, 30.0)


def test_the_inflation_model_reproduces_a_quadratic_and_interpolates_unseen_levels():
    """Fitted on the 27 states of {0, 10, 20} ml, the degree-2 model (10 terms) is exact for a
    quadratic c_0(p), also at volumes never recorded (5, 15, 7.5 ml): to 1e-9 relative. A
    touch frame of an unseen state calibrates to its analytic 0.05 pattern. Catches missing
    cross terms, a wrong scale, a fit over the wrong axis, and degree 1 (shown not exact)."""
    rec = quadratic_recording()
    model = InflationModel.fit(rec)
    assert len(model.terms) == 10 and model.degree == 2 and len(model.states) == 27
    for p in [(5.0, 15.0, 7.5), (15.0, 5.0, 0.0), (20.0, 20.0, 20.0), (2.5, 17.5, 12.5)]:
        np.testing.assert_allclose(model.predict(p), c0_true(p), rtol=1e-9)
    np.testing.assert_allclose(model.residual_rel, 0.0, atol=1e-12)
    unseen = quadratic_recording((5.0, 15.0), rest=False, seed=0)
    ds = touch_dataset(unseen, reference=model)
    patterns = np.random.default_rng(0).uniform(0.2, 1.0, (19, P))
    np.testing.assert_allclose(ds.x, 0.05 * patterns[ds.y], rtol=1e-5, atol=1e-7)
    assert ds.reference["mode"] == "inflation"
    # the string form fits on the recording itself: the same model
    np.testing.assert_allclose(
        touch_dataset(rec, reference="inflation").x, touch_dataset(rec, reference=model).x
    )
    linear = InflationModel.fit(rec, degree=1)
    assert np.abs(linear.predict((5.0, 15.0, 7.5)) / c0_true((5.0, 15.0, 7.5)) - 1).max() > 1e-3


def test_the_inflation_model_json_round_trip_and_refusals():
    """to_json → from_json gives the same predictions (plain JSON, NaN as null for an unmeasured
    channel); too few states, a wrong chamber count, other pairs and a foreign document are
    errors naming what is wrong."""
    import json

    rec = quadratic_recording()
    keep = np.arange(P - 1)  # the last channel not measured
    model = InflationModel.fit(rec, keep)
    doc = json.loads(json.dumps(model.to_json(), allow_nan=False))
    back = InflationModel.from_json(doc)
    p = (5.0, 15.0, 7.5)
    np.testing.assert_array_equal(back.predict(p)[keep], model.predict(p)[keep])
    assert np.isnan(back.predict(p)[-1])
    two = quadratic_recording((0.0, 20.0))  # 8 states, no p_i² term determined
    with pytest.raises(EctskinError, match=r"8 state\(s\) .* determine 7 of the 10 terms"):
        InflationModel.fit(two)
    with pytest.raises(EctskinError, match=r"fitted on 3 chamber volume\(s\), got an inflation of 2"):
        model.predict((1.0, 2.0))
    with pytest.raises(EctskinError, match=r"expected format 'ectskin.inflation_reference'"):
        InflationModel.from_json({"format": "other"}, "split.json")
    assert monomials(2, 2) == [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]


def test_state_reference_function_matches_touch_reference():
    rec = quadratic_recording((0.0, 10.0))
    refs = state_reference(rec)
    assert set(refs) == {t.name for t in rec.trials}
    np.testing.assert_allclose(refs["s3_touch"], c0_true(rec.trial("s3_touch").inflation))


def test_options_and_profile_defaults():
    """The CLI's reference list equals the calibration's; the paper's profiles keep the rest
    state (the paper's Eq. 2), the robust profile follows the inflation; a reference for
    another task is refused."""
    assert REFERENCES == REFERENCE_OPTIONS
    assert PROFILE_REFERENCE["paper"] == PROFILE_REFERENCE["quick"] == "auto"
    assert TrainConfig().reference_for("touch") == "auto"
    assert TrainConfig(profile="robust").reference_for("touch") == PROFILE_REFERENCE["robust"]
    assert TrainConfig(profile="robust", reference="rest").reference_for("touch") == "rest"
    assert TrainConfig(profile="robust").reference_for("track") == "auto"
    with pytest.raises(EctskinError, match=r"reference 'state' applies to task 'touch' only"):
        TrainConfig(reference="state").reference_for("contact")
    with pytest.raises(EctskinError, match=r"Invalid value for .*'reference'"):
        TrainConfig(reference="pump").reference_for("touch")
    rec = quadratic_recording((0.0, 10.0))
    assert reference_doc(rec, "auto") == {"mode": "rest"}


def test_class_mixup_mixes_each_frame_with_one_of_its_own_class():
    """``mixup_pairs="class"`` (the robust recipe's within-class mixup): every frame is mixed
    with a frame of the same class (its label kept), x_i' = λ_i x_i + (1 − λ_i) x_j, checked
    against the draws redone by hand; "any" may pair across classes. Catches partners of
    another class, a label that changes, λ applied the wrong way round."""
    import torch

    from ectskin.learn.augment import augment_touch_batch

    y = torch.tensor([0, 1, 1, 2, 0, 1, 2, 2, 0, 1])
    x = torch.arange(10, dtype=torch.float32)[:, None] * torch.ones(1, 3)  # row i holds i
    out, y_a, y_b, lam = augment_touch_batch(
        x, y, np.random.default_rng(4), mixup_alpha=1.0, mixup_pairs="class"
    )
    assert torch.equal(y_a, y) and torch.equal(y_b, y)
    rng = np.random.default_rng(4)
    lam_ref = rng.beta(1.0, 1.0, size=10).astype(np.float32)
    order = np.arange(10)
    for c in (0, 1, 2):
        idx = np.flatnonzero(y.numpy() == c)
        order[idx] = idx[rng.permutation(idx.size)]
    np.testing.assert_allclose(lam.numpy(), lam_ref)
    want = lam_ref * np.arange(10) + (1 - lam_ref) * order
    np.testing.assert_allclose(out[:, 0].numpy(), want, rtol=1e-6)
    assert (y.numpy()[order] == y.numpy()).all() and (order != np.arange(10)).any()
    _, _, y_any, _ = augment_touch_batch(x, y, np.random.default_rng(4), mixup_alpha=1.0)
    assert (y_any != y).any()
