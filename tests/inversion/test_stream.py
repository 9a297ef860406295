"""A smaller count screened where a stream's warm start explains the frame
(``inversion.stream.screened``): which fits run on which budget, by a fake optimiser that records
its calls (the live head's test, tests/live/test_inversion_head.py, checks the answers); and its
start, the warm fit's strongest fingers (``inversion.stream.strongest``), on a hand-made model."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion.lm import MAX_NFEV
from ectskin.inversion.result import Fit
from ectskin.inversion.stream import SCREEN_FACTOR, SCREEN_NFEV, screened, strongest

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


class _TwoChannelModel:
    """A model whose front finger's signal is s on channel 0 and back finger's s on channel 1."""

    faces = ("front", "back")

    def signal(self, face, mode, x):
        d = np.zeros(2)
        d[self.faces.index(face)] = x[2]
        return d, np.zeros((2, 3))


def test_the_screened_start_is_the_warm_fits_strongest_fingers_in_noise_units():
    fit = Fit([(0, 0, np.array([1.0, 2.0, 1.0])), (1, 0, np.array([3.0, 4.0, 5.0]))],
              np.zeros(1), 1.0, True)
    m = _TwoChannelModel()
    # by hand: front 1.0 / 1 = 1 σ, back 5.0 / 10 = 0.5 σ: the front finger (in pF the back)
    (fi, mi, x), = strongest(m, fit, 1, np.array([1.0, 10.0]))
    assert (fi, mi) == (0, 0) and x.tolist() == [1.0, 2.0, 1.0]
    # with equal noise the back finger
    assert strongest(m, fit, 1, np.array([1.0, 1.0]))[0][0] == 1
    # all of them in the fit's order (the back finger is the stronger here), copies
    both = strongest(m, fit, 2, np.array([1.0, 1.0]))
    assert [f[0] for f in both] == [0, 1]
    both[0][2][0] = 99.0
    assert fit.fingers[0][2][0] == 1.0
    for k in (0, 3):
        with pytest.raises(EctskinError, match="strongest: k must be 1..2"):
            strongest(m, fit, k, np.ones(2))
