"""A smaller count screened where a stream's warm start explains the frame
(``inversion.stream.screened``): which fits run on which budget, by a fake optimiser that records
its calls (the live head's test, tests/live/test_inversion_head.py, checks the answers)."""

from __future__ import annotations

import numpy as np

from ectskin.inversion.lm import MAX_NFEV
from ectskin.inversion.result import Fit
from ectskin.inversion.stream import SCREEN_FACTOR, SCREEN_NFEV, screened

START = [(0, 0, np.array([1.0, 2.0, 0.5]))]
GATE = 40.0


def _optimiser(chi2_first: float, converged_first: bool):
    """A fake fit_fingers: its first call returns ``chi2_first`` (converged or not) at a moved
    point, later calls χ² 1 (converged); every call's (start, max_nfev) is recorded."""
    calls = []

    def fit(m, delta, sigma, start, coupled, max_nfev=MAX_NFEV):
        calls.append((start, max_nfev))
        if len(calls) == 1:
            moved = [(fi, mi, x + 1.0) for fi, mi, x in start]
            return Fit(moved, np.zeros(1), chi2_first, converged_first)
        return Fit(start, np.zeros(1), 1.0, True)

    return fit, calls


def test_a_fit_far_from_its_gate_stops_at_the_screen():
    fit, calls = _optimiser(SCREEN_FACTOR * GATE * 1.01, False)
    f = screened(fit, None, None, None, START, False, lambda f: GATE)
    assert [n for _, n in calls] == [SCREEN_NFEV] and f.chi2 > SCREEN_FACTOR * GATE
    assert not f.converged


def test_a_fit_near_its_gate_goes_on_from_where_it_stopped():
    fit, calls = _optimiser(SCREEN_FACTOR * GATE * 0.99, False)
    f = screened(fit, None, None, None, START, False, lambda f: GATE)
    assert [n for _, n in calls] == [SCREEN_NFEV, MAX_NFEV]
    np.testing.assert_array_equal(calls[1][0][0][2], START[0][2] + 1.0)  # from the screened point
    assert f.chi2 == 1.0 and f.converged


def test_a_converged_fit_is_the_answer_whatever_its_chi2():
    for chi2 in (1.0, 1e9):
        fit, calls = _optimiser(chi2, True)
        assert screened(fit, None, None, None, START, False, lambda f: GATE).chi2 == chi2
        assert len(calls) == 1
