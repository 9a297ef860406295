"""The twin's coverage trials: every touch region in every inflation state of an experiment."""

from dataclasses import replace

import pytest

from ectskin._check import EctskinError
from ectskin.twin import Protocol
from ectskin.twin.coverage import COVERAGE_STREAM, coverage_protocol
from ectskin.twin.protocol import plan_trials


@pytest.mark.parametrize("levels, repeats", [((0.0, 10.0, 20.0), 2), ((0.0, 20.0), 1)])
def test_every_region_is_touched_in_every_state(layout, levels, repeats):
    base = Protocol(seed=3, levels_ml=levels)
    cov = coverage_protocol(base, layout, repeats=repeats)
    plans = plan_trials(cov, layout)
    touches = [p for p in plans if p.kind == "touch"]
    # the paper's layout has as many regions on each face: each `repeats` times per state
    want = sorted((r.id, s) for r in layout.regions for s in base.states() for _ in range(repeats))
    assert sorted((p.region, p.inflation) for p in touches) == want
    # one no-contact trial per state: the rest readout each state is calibrated against
    assert sorted(p.inflation for p in plans if p.kind == "no_contact") == sorted(base.states())
    # one point held per trial, inside its region (uniform placement)
    for p in touches:
        reg = layout.region(p.region)
        assert len(p.touch_uv_mm) == 1 and p.surface == reg.surface
        (u, v), = p.touch_uv_mm
        assert reg.u_mm[0] <= u <= reg.u_mm[1] and reg.v_mm[0] <= v <= reg.v_mm[1]
    assert cov.n_frames == 90 and cov.touch_placement == "uniform" and cov.second_finger == 0


def test_coverage_keeps_the_experiment_but_not_its_draws(layout):
    base = Protocol(seed=5, push_max_n=1.0, force_range_n=(0.5, 1.5), stream=2)
    cov = coverage_protocol(base, layout, duration_s=2.0)
    for name in ("seed", "levels_ml", "readout", "push_max_n", "force_range_n", "finger_variability"):
        assert getattr(cov, name) == getattr(base, name), name
    assert cov.stream == COVERAGE_STREAM + 2 and cov.n_frames == 60
    # streams of its own: no draw shared with the experiment of the same seed
    assert cov.rng(1, 0).random() != base.rng(1, 0).random()
    assert cov.rng(1, 0).random() != Protocol(seed=5).rng(1, 0).random()


def test_a_layout_without_touch_regions_or_no_repeat_is_refused(layout):
    with pytest.raises(EctskinError, match="no touch regions"):
        coverage_protocol(Protocol(), replace(layout, regions=[]))
    with pytest.raises(EctskinError, match="repeats must be a whole number >= 1, got 0"):
        coverage_protocol(Protocol(), layout, repeats=0)
