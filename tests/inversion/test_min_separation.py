"""Two fingertips cannot overlap: a two-finger answer whose fingertips' centres lie closer than
``Inversion(min_separation_mm=...)`` on one face is not a configuration of two fingers (it is
how a fit splits one finger larger or softer than the field's in two), and the frame keeps its
best answer of fewer fingers. Checked on the analytic flat skin with two fingers pressing close
together (counted two without the rule, one with it) and far apart (two either way), and the
default against a field's own fingertip."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import Inversion
from ectskin.inversion.result import Fit

STATE = (0.0,)


def _pressing(result):
    return sorted((round(f.u_mm, 1), round(f.v_mm, 1)) for f in result.fingers if f.contact)


@pytest.mark.parametrize("apart_mm, counted_with_rule", [(9.0, 1), (30.0, 2)])
def test_fingertips_closer_than_the_rule_are_one_answer(analytic_field, apart_mm,
                                                        counted_with_rule):
    u = (-apart_mm / 2, apart_mm / 2)
    frame = analytic_field.untouched + sum(
        analytic_field.delta("front", x, 30.0, 1.2) for x in u)
    free = Inversion({STATE: analytic_field}, min_separation_mm=0.0).fit(frame, STATE)
    ruled = Inversion({STATE: analytic_field}, min_separation_mm=16.0).fit(frame, STATE)
    assert len(_pressing(free)) == 2  # the two presses are there to be found
    assert len(_pressing(ruled)) == counted_with_rule
    if counted_with_rule == 2:
        assert _pressing(ruled) == _pressing(free)


def test_the_rule_measures_the_fingertips_centres(analytic_field):
    inv = Inversion({STATE: analytic_field}, min_separation_mm=16.0)
    m = inv.model(STATE)
    press, hover = m.modes.index("contact"), m.modes.index("hover")

    def fit(a, b):
        return Fit([a, b], np.zeros(0), 0.0, True)

    at = lambda face, mode, u, v, s: (face, mode, np.array([u, v, s]))  # noqa: E731
    assert inv._overlap(m, fit(at(0, press, 0, 30, 1.0), at(0, press, 10, 30, 1.0)))
    assert not inv._overlap(m, fit(at(0, press, 0, 30, 1.0), at(0, press, 0, 47, 1.0)))
    # a hovering finger 20 mm above the other's point lies clear of it; 5 mm above it does not
    assert not inv._overlap(m, fit(at(0, press, 0, 30, 1.0), at(0, hover, 0, 30, math.log(20))))
    assert inv._overlap(m, fit(at(0, press, 0, 30, 1.0), at(0, hover, 3, 30, math.log(5))))
    if len(m.faces) > 1:  # on two faces: never (the body lies between them)
        assert not inv._overlap(m, fit(at(0, press, 0, 30, 1.0), at(1, press, 0, 30, 1.0)))


def test_the_default_is_twice_the_fields_fingertip(small_field, small_spec, analytic_field):
    inv = Inversion({small_spec.inflation_ml: small_field})
    assert inv.min_separation_mm == 2 * small_spec.finger.radius_mm
    # a field without a fingertip of its own (the analytic skin): no rule
    assert Inversion({STATE: analytic_field}).min_separation_mm == 0.0
    with pytest.raises(EctskinError, match="min_separation_mm"):
        Inversion({STATE: analytic_field}, min_separation_mm=-1.0)
