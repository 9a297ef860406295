"""The fit's Levenberg–Marquardt runs MINPACK's ``lmder`` through ``scipy.optimize.leastsq``
(cheaper per call than ``least_squares``): it must take the steps ``least_squares(method="lm",
x_scale="jac")`` takes with the same tolerances, so the answers are those of the slower call to
the last bit (the accuracy tests of this folder hold for both)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ectskin.inversion import Inversion
from ectskin.inversion import lm as lm_module  # the module that calls leastsq
from ectskin.twin.readout import ReadoutConfig, noise_pf

#: least_squares' status → MINPACK's info (scipy's FROM_MINPACK_TO_COMMON, inverted)
STATUS_TO_INFO = {2: 1, 3: 2, 4: 3, 1: 4, 0: 5}


def _via_least_squares(fun, x0, Dfun, maxfev, ftol, xtol, gtol):
    sol = least_squares(fun, x0, jac=Dfun, method="lm", x_scale="jac", max_nfev=maxfev,
                        ftol=ftol, xtol=xtol, gtol=gtol)
    return sol.x, STATUS_TO_INFO[sol.status]


def _frames(field, rng):
    """Noisy frames of one finger pressing, one hovering and two pressing."""
    cases = [[(-4.2, 21.3, 1.1, 0.0)], [(6.3, 37.9, 0.0, 2.5)],
             [(-10.5, 12.2, 1.4, 0.0), (9.1, 44.8, 0.8, 0.0)], [(0.7, 30.1, 0.5, 0.0)]]
    out = []
    for fingers in cases:
        c = field.untouched.copy()
        for u, v, f, h in fingers:
            c = c + field.delta("front", u, v, f, h)
        out.append(c + rng.standard_normal(c.size) * noise_pf(c, ReadoutConfig()))
    return out


def test_leastsq_takes_the_steps_of_least_squares_lm(analytic_field, monkeypatch):
    inv = Inversion({(0.0,): analytic_field})
    frames = _frames(analytic_field, np.random.default_rng(4))
    got = [inv.fit(y, (0.0,)) for y in frames]
    monkeypatch.setattr(lm_module, "leastsq", _via_least_squares)
    want = [inv.fit(y, (0.0,)) for y in frames]
    assert [r.n_fingers for r in got] == [1, 1, 2, 1]
    for a, b in zip(got, want):
        assert a.fingers == b.fingers  # every number, to the last bit
        assert a.bic_by_count == b.bic_by_count and a.converged == b.converged
        assert a.nuisance == b.nuisance
