"""`ectskin live` refuses a touch run calibrated at each state's own rest readout: the live
stream is calibrated against the rest state's readout only, so such a run would see frames
unlike those it learnt from."""

from __future__ import annotations

import pytest

from ectskin._check import EctskinError
from ectskin.commands.live import _check_touch_reference
from ectskin.learn.predict.touch import TouchPredictor


def _predictor(extra: dict) -> TouchPredictor:
    p = TouchPredictor.__new__(TouchPredictor)  # the payload is all the check reads
    p.payload = {"extra": extra}
    return p


@pytest.mark.parametrize("mode", ["state", "inflation", "state-offset", "inflation-offset"])
def test_a_run_that_follows_the_inflation_is_refused(mode):
    p = _predictor({"reference": {"mode": mode}})
    assert p.reference_mode == mode
    with pytest.raises(EctskinError, match=rf"--touch-model runs/x: .*reference '{mode}'.*--reference rest"):
        _check_touch_reference(p, "runs/x")


@pytest.mark.parametrize("extra", [{}, {"reference": {"mode": "rest"}}, {"reference": None}])
def test_a_rest_calibrated_run_is_taken(extra):
    p = _predictor(extra)
    assert p.reference_mode in (None, "rest")
    _check_touch_reference(p, "runs/x")
    _check_touch_reference(None, None)  # no touch model at all
