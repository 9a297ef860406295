"""The skin's own untouched readout (``Inversion(untouched=...)``), the check whether a hovering
finger presses (``press_check``), and what the reproduction's step makes of them
(:func:`ectskin.io.calibration.untouched_readouts`, the slots of hovering fingers).

References: frames made from the closed-form field (``conftest``) at known parameters on top of
an untouched readout that differs from the field's by a per-channel pattern (what a skin's body
does against the field's mesh: no common gain or offset absorbs it); a light press whose signal
is 0.9 of the field's (a smaller fingertip), which the fit without the check reports as a
finger hovering at the field's lowest height; means computed here by hand.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import FingerEstimate, Inversion, InversionResult
from ectskin.inversion.frames import results_to_arrays
from ectskin.io.calibration import untouched_readouts
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS
from ectskin.pipeline.inversion import prediction_columns

STATE = (0.0,)


def _pattern(n: int) -> np.ndarray:
    """A per-channel offset of about 20 noise σ, orthogonal to nothing in particular."""
    return 2e-3 * np.sin(1.7 * np.arange(n) + 0.3)


@pytest.mark.parametrize("u, v, f", [(3.3, 21.7, 1.1), (-8.1, 40.2, 0.7)])
def test_a_press_on_the_skins_own_untouched_readout_comes_back(analytic_field, u, v, f):
    """The frame is the measured untouched readout plus the field's signal: given that readout
    the point and force come back to the optimiser's tolerance (also with a channel masked);
    compared with the field's untouched readout instead (the old behaviour) the pattern moves
    the point by millimetres."""
    measured = analytic_field.untouched + _pattern(analytic_field.n_pairs)
    y = measured + analytic_field.delta("front", u, v, f)
    cal = Inversion({STATE: analytic_field}, untouched={STATE: measured})
    r = cal.fit(y, STATE)
    assert r.n_fingers == 1 and r.fingers[0].contact
    e = r.fingers[0]
    np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n], [u, v, f], atol=1e-4)
    masked = y.copy()
    masked[3] = np.nan
    e = cal.fit(masked, STATE).fingers[0]
    np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n], [u, v, f], atol=1e-4)
    e = Inversion({STATE: analytic_field}).fit(y, STATE).fingers[0]
    assert np.hypot(e.u_mm - u, e.v_mm - v) > 1.0


def test_the_measured_untouched_readout_alone_is_no_finger(analytic_field):
    measured = analytic_field.untouched + _pattern(analytic_field.n_pairs)
    r = Inversion({STATE: analytic_field}, untouched={STATE: measured}).fit(measured * 1.001, STATE)
    assert r.n_fingers == 0
    assert r.nuisance["gain"] == pytest.approx(1e-3, rel=1e-6)


def test_a_state_missing_from_untouched_keeps_the_fields(analytic_field):
    y = analytic_field.untouched + analytic_field.delta("front", 3.3, 21.7, 1.1)
    other = {(5.0,): analytic_field.untouched + _pattern(analytic_field.n_pairs)}
    e = Inversion({STATE: analytic_field}, untouched=other).fit(y, STATE).fingers[0]
    np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n], [3.3, 21.7, 1.1], atol=1e-4)


@pytest.mark.parametrize("bad", [np.ones(3), np.full(15, np.nan), -np.ones(15)])
def test_a_bad_untouched_readout_is_refused_by_name(analytic_field, bad):
    with pytest.raises(EctskinError, match=r"untouched\[\[0\.0\]\]"):
        Inversion({STATE: analytic_field}, untouched={STATE: bad})


def test_a_bad_contact_bias_is_refused(analytic_field):
    with pytest.raises(EctskinError, match="contact_bias"):
        Inversion({STATE: analytic_field}, contact_bias=-1.0)


@pytest.mark.parametrize("u, v", [(0.0, 30.0), (-8.1, 40.2)])
def test_a_light_press_smaller_than_the_fields_is_called_pressing(analytic_field, u, v):
    """0.9 of the field's signal of a press at its least force: the plain fit finds a finger
    hovering at the field's lowest height (the old answer, asserted so that the case stays a
    case); with ``press_check`` the same finger presses, at the least force, at the point."""
    y = analytic_field.untouched + 0.9 * analytic_field.delta("front", u, v, 0.3)
    old = Inversion({STATE: analytic_field}).fit(y, STATE)
    assert old.n_fingers == 1 and not old.fingers[0].contact
    assert old.fingers[0].height_mm == pytest.approx(0.5, abs=1e-3)
    r = Inversion({STATE: analytic_field}, press_check=True).fit(y, STATE)
    assert r.n_fingers == 1 and r.fingers[0].contact
    e = r.fingers[0]
    assert e.force_n == pytest.approx(0.3, abs=0.02)
    assert np.hypot(e.u_mm - u, e.v_mm - v) < 0.5
    assert r.bic == r.bic_by_count[1]


@pytest.mark.parametrize("h", [1.5, 4.0])
def test_a_finger_that_hovers_stays_hovering(analytic_field, h):
    """A noise-free hover within the field's heights: pressing fits far worse, so the check
    leaves it, to the optimiser's tolerance."""
    y = analytic_field.readout("front", 2.0, 33.0, 0.0, h)
    r = Inversion({STATE: analytic_field}, press_check=True).fit(y, STATE)
    assert r.n_fingers == 1 and not r.fingers[0].contact
    e = r.fingers[0]
    np.testing.assert_allclose([e.u_mm, e.v_mm, e.height_mm], [2.0, 33.0, h], atol=1e-4)


# ---------------------------------------------------------------------------- the step's part
def _trial(name, state, frames, kind):
    return SimpleNamespace(name=name, inflation=state, capacitance=np.asarray(frames, float),
                           meta={"kind": kind}, region=0, labels=np.zeros(len(frames), int))


def test_untouched_readouts_average_the_no_contact_trials_outside_the_test_trials():
    a, b = (0.0, 0.0), (20.0, 0.0)
    rec = SimpleNamespace(trials=[
        _trial("rest_a", a, [[1.0, 2.0, 3.0], [3.0, np.nan, 5.0]], "no_contact"),
        _trial("rest_a2", a, [[2.0, 4.0, 4.0]], "no_contact"),
        _trial("touch_a", a, [[9.0, 9.0, 9.0]], "touch"),
        _trial("rest_b_test", b, [[7.0, 7.0, 7.0]], "no_contact"),
        _trial("rest_c", (10.0, 0.0), [[5.0, 5.0, 5.0]], "no_contact"),  # no field: ignored
    ])
    out = untouched_readouts(rec, {a: object(), b: object()}, exclude=["rest_b_test"])
    assert set(out) == {a}
    np.testing.assert_allclose(out[a]["pF"], [2.0, 3.0, 4.0])  # per channel, the finite ones
    assert out[a]["trials"] == ["rest_a", "rest_a2"]
    rec.trials[1] = _trial("rest_a2", a, [[2.0, np.nan, 4.0]], "no_contact")
    rec.trials[0] = _trial("rest_a", a, [[1.0, np.nan, 3.0]], "no_contact")
    assert untouched_readouts(rec, {a: object()}) == {}  # a channel never read: the field's


def _hover(u, v, h):
    return FingerEstimate(face="front", contact=False, u_mm=u, v_mm=v, force_n=0.0, height_mm=h,
                          u_se_mm=0.1, v_se_mm=0.1, force_se_n=0.0, height_se_mm=0.1)


def test_with_no_press_the_lowest_hovering_finger_takes_slot_0(analytic_field):
    """Two hovering fingers, the first one (in the fit's order) higher: the lower one answers
    for the frame's point, the higher takes slot 1, and no finger is counted."""
    r = InversionResult(n_fingers=2, fingers=(_hover(-10.0, 20.0, 8.0), _hover(10.0, 45.0, 1.5)),
                        log_likelihood=0.0, bic=0.0, converged=True, bic_by_count=(1.0, 1.0, 0.0))
    pred = prediction_columns(results_to_arrays([r]), ["front"],
                              {"front": analytic_field.spec.window})
    u = len(PRED_COLUMNS) + SLOT_COLUMNS.index("u_mm")
    np.testing.assert_allclose(pred[0, u: u + 2], [10.0, 45.0])
    np.testing.assert_allclose(pred[0, u + len(SLOT_COLUMNS): u + len(SLOT_COLUMNS) + 2],
                               [-10.0, 20.0])
    assert pred[0, 0] == 0 and pred[0, 2] == 1  # none presses; one hovers below 15 mm


def test_the_press_check_prefers_pressing_within_contact_bias_times_chi2_per_dof(analytic_field,
                                                                               monkeypatch):
    """The rule itself, on the fit of a finger hovering 1.5 mm high (above the field's lowest
    height) with its χ² set by hand to c, with the pressing refit's χ² p = c (1 + 3/dof)
    (dof: channels less the hovering fit's parameters): ``contact_bias`` 3.5 keeps the
    pressing fit, 2.5 the hovering one. The refit is the one at the hovering point: the start
    at a pressing node where that one fails (the next test) is left out here."""

    y = analytic_field.readout("front", 0.0, 30.0, 0.0, 1.5)
    for bias, pressing in [(3.5, True), (2.5, False)]:
        inv = Inversion({STATE: analytic_field}, press_check=True, contact_bias=bias)
        m = inv.model(STATE)
        sigma = inv._sigma(m, y, 1)
        delta = y - m.untouched
        monkeypatch.setattr(m.table, "starts", lambda *a, **k: [])
        hover = inv._fit_fingers(m, delta, sigma, [(0, 1, np.array([0.0, 30.0, np.log(2.0)]))])
        assert hover.fingers[0][2][2] > np.log(0.5) + 0.01  # not at the lowest height
        alt = inv._fit_fingers(m, delta, sigma, [(0, 0, np.array([*hover.fingers[0][2][:2], 0.3]))])
        dof = m.n_pairs - hover.n_params
        c = alt.chi2 / (1 + 3 / dof)
        assert c / dof > 1
        got = inv._pressing(m, delta, sigma, replace(hover, chi2=c))
        assert (got.fingers[0][1] == 0) is pressing


@pytest.mark.parametrize("u, v", [(-17, 3), (-17, 50), (-17, 57), (0, 3), (0, 57), (10, 3),
                                  (17, 3), (17, 50), (17, 57)])
def test_where_pressing_at_the_hovering_point_fails_the_check_starts_at_the_pressing_node(
        analytic_field, u, v):
    """The rule's other half, on a two-finger frame whose fit has the second finger hovering far
    from its press (the search's hover can lie there, the first finger's signal taking up the
    rest), its χ² set by hand to 1 000: refitted pressing from its own point, LM stops at a
    local minimum of χ² above 2e4, which fails the check (the finger stayed hovering before);
    from the pressing node nearest what the first finger leaves, both presses come back to the
    optimiser's tolerance, and that fit is kept."""
    from ectskin.inversion.model import MODES
    from ectskin.inversion.result import Fit

    inv = Inversion({STATE: analytic_field}, max_fingers=2, press_check=True)
    m = inv.model(STATE)
    a, b = (-8.0, 12.0, 1.0), (4.0, 40.0, 1.2)
    y = (analytic_field.readout("front", *a, 0.0) + analytic_field.readout("front", *b, 0.0)
         - analytic_field.untouched)
    delta, sigma = y - m.untouched, inv._sigma(m, y, 1)
    press, hover = MODES.index("contact"), MODES.index("hover")
    x = np.array([u, v, np.log(5.0)])
    fit = Fit([(0, press, np.array(a)), (0, hover, x)], np.zeros(m.N.shape[1]), 1e3, True)
    near = inv._fit_fingers(m, delta, sigma, [(0, press, np.array(a)),
                                              (0, press, np.array([*x[:2], 0.3]))])
    assert near.chi2 > 2e4  # the case stays a case: pressing at the hovering point fails
    got = inv._pressing(m, delta, sigma, fit)
    assert [MODES[mode] for _, mode, _ in got.fingers] == ["contact", "contact"]
    np.testing.assert_allclose([xx for *_, xx in got.fingers], [a, b], atol=1e-3)
