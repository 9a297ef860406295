"""Paper Eq. 2 and the choice of the reference state (ectskin.io.calibration)."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io.calibration import (
    calibrate,
    check_reference,
    is_no_contact,
    rest_trials,
    touch_reference,
)
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout

LAYOUT = default_layout()
P = LAYOUT.n_pairs


def _trial(name, cap, *, inflation=(0, 0, 0), region=0, kind=None, meta=None):
    n = cap.shape[0]
    m = dict(meta or {})
    if kind is not None:
        m["kind"] = kind
    return Trial(
        name,
        cap,
        np.arange(n) / 30.0,
        np.full(n, region),
        inflation=inflation,
        region=region,
        meta=m,
    )


# --------------------------------------------------------------------------- Eq. 2
def test_calibrate_hand_computed():
    frames = np.array([[2.0, 3.0, 0.5], [1.0, 6.0, 1.5]])
    ref = np.array([1.0, 3.0, 1.0])
    c = calibrate(frames, ref)
    # (c_t - c_0) / c_0 by hand
    np.testing.assert_array_equal(c, [[1.0, 0.0, -0.5], [0.0, 1.0, 0.5]])
    assert c.dtype == np.float32
    one = calibrate(np.array([1.2, 3.3, 1.0]), ref)
    assert one.shape == (3,)
    np.testing.assert_allclose(one, [0.2, 0.1, 0.0], rtol=1e-6, atol=1e-7)


def test_calibrate_per_frame_reference():
    frames = np.array([[2.0, 2.0], [3.0, 3.0]])
    ref = np.array([[1.0, 2.0], [3.0, 1.5]])
    np.testing.assert_allclose(calibrate(frames, ref), [[1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(EctskinError, match="3 rows"):
        calibrate(np.ones((3, 2)), ref)


@pytest.mark.parametrize(
    "ref, what",
    [
        ([1.0, 0.0, 2.0], "is 0"),
        ([1.0, 1e-9, 2.0], "is 1e-09"),
        ([1.0, np.nan, 2.0], "is nan"),
        ([1.0, np.inf, 2.0], "is inf"),
    ],
)
def test_bad_reference_names_the_channel(ref, what):
    with pytest.raises(EctskinError) as e:
        calibrate(
            np.ones((4, 3)), np.array(ref), source="trial 't1'", pair_names=["A-B", "A-C", "B-C"]
        )
    msg = str(e.value)
    assert "trial 't1'" in msg and "channel 1 ('A-C')" in msg and what in msg


def test_all_zero_reference_refused():
    with pytest.raises(EctskinError, match="channel 0"):
        check_reference(np.zeros(4), 4)


def test_reference_wrong_shape():
    with pytest.raises(EctskinError, match=r"shape \(3,\)"):
        check_reference(np.ones(4), 3)


def test_negative_reference_is_allowed_eq2_as_written():
    # Eq. 2 is defined for any non-zero c_0; (−1 − (−2)) / (−2) = −0.5
    np.testing.assert_allclose(calibrate(np.array([[-1.0]]), np.array([-2.0])), [[-0.5]])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_frame_names_trial_frame_channel(bad):
    frames = np.ones((5, 3))
    frames[3, 2] = bad
    with pytest.raises(EctskinError) as e:
        calibrate(
            frames, np.ones(3), source="trial 'touch_007'", pair_names=["E1-E2", "E1-E3", "E2-E3"]
        )
    msg = str(e.value)
    assert "trial 'touch_007'" in msg and "frame 3" in msg and "channel 2 ('E2-E3')" in msg


def test_nonfinite_frames_propagate_only_when_allowed():
    frames = np.ones((3, 2))
    frames[1, 0] = np.nan
    c = calibrate(frames, np.full(2, 0.5), allow_nonfinite=True)
    assert np.isnan(c[1, 0]) and np.all(np.isfinite(np.delete(c.ravel(), 2)))
    np.testing.assert_array_equal(c[0], [1.0, 1.0])


def test_float32_overflow_refused():
    with pytest.raises(EctskinError, match="too large for float32"):
        calibrate(np.array([[1e300, 1.0]]), np.array([1.0, 1.0]))


# --------------------------------------------------------------------------- references
def _paper_like():
    rng = np.random.default_rng(1)
    base = rng.uniform(0.5, 2.0, P)
    rest = base + rng.normal(0, 1e-3, (20, P))
    inflated = 1.3 * base + rng.normal(0, 1e-3, (20, P))
    touch = base * 1.05 + rng.normal(0, 1e-3, (20, P))
    trials = [
        _trial("s1_rest", inflated, inflation=(20, 0, 0), kind="no_contact"),
        _trial("s0_rest", rest, inflation=(0, 0, 0), kind="no_contact"),
        _trial("s0_touch", touch, inflation=(0, 0, 0), region=4, kind="touch"),
    ]
    return Recording(LAYOUT, trials, 30.0), rest


def test_auto_reference_is_mean_of_uninflated_no_contact_trial():
    rec, rest = _paper_like()
    refs = touch_reference(rec)
    assert set(refs) == {"s1_rest", "s0_rest", "s0_touch"}
    for r in refs.values():
        np.testing.assert_allclose(r, rest.mean(axis=0), rtol=1e-12)
    assert [t.name for t in rest_trials(rec)] == ["s0_rest"]


def test_rest_state_without_kind_uses_region_and_labels():
    t = Trial("x", np.ones((2, P)), [0, 1], [0, 0], inflation=(0, 0, 0))
    assert is_no_contact(t)
    t2 = Trial("y", np.ones((2, P)), [0, 1], [0, 3], inflation=(0, 0, 0))
    assert not is_no_contact(t2)


def test_no_rest_state_is_an_error():
    rec, _ = _paper_like()
    rec2 = Recording(LAYOUT, [rec.trials[0], rec.trials[2]], 30.0)
    with pytest.raises(EctskinError, match="no rest-state trial"):
        touch_reference(rec2)


def test_non_inflatable_recording_uses_its_no_contact_trials():
    a = np.full((4, P), 2.0)
    b = np.full((4, P), 4.0)
    rec = Recording(
        LAYOUT,
        [
            _trial("a", a, inflation=(), kind="no_contact"),
            _trial("b", b, inflation=(), region=2, kind="touch"),
        ],
        30.0,
    )
    np.testing.assert_array_equal(touch_reference(rec)["b"], np.full(P, 2.0))


def test_explicit_and_meta_references():
    rec, _ = _paper_like()
    ref = np.linspace(1, 2, P)
    assert all(np.array_equal(r, ref) for r in touch_reference(rec, reference=ref).values())
    with pytest.raises(EctskinError, match="channel 3"):
        touch_reference(rec, reference=np.where(np.arange(P) == 3, 0.0, ref))
    with pytest.raises(EctskinError, match="allowed values"):
        touch_reference(rec, reference="first")
    with pytest.raises(EctskinError, match="meta has no 'reference'"):
        touch_reference(rec, reference="meta")


def test_auto_prefers_per_trial_meta_references():
    ref_a = [1.0] * P
    ref_b = [2.0] * (P - 1) + [None]  # last pair unmeasured
    rec = Recording(
        LAYOUT,
        [
            _trial("a", np.ones((3, P)), kind="touch", region=1, meta={"reference": ref_a}),
            _trial("b", np.ones((3, P)), kind="touch", region=1, meta={"reference": ref_b}),
        ],
        30.0,
    )
    refs = touch_reference(rec, channels=np.arange(P - 1))
    np.testing.assert_array_equal(refs["a"], np.ones(P - 1))
    np.testing.assert_array_equal(refs["b"], np.full(P - 1, 2.0))
    # with the unmeasured channel included, its missing reference is refused by name
    with pytest.raises(EctskinError, match=f"channel {P - 1}"):
        touch_reference(rec)
