"""Simulating with the field reading (``Protocol.response="field"``): the same bits for any
number of workers, the same trials as the solve reading within the models' errors, the fields
checked at the door, and an experiment's own random streams (``Protocol.stream``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.twin import Protocol, plan_trials, simulate_experiment
from ectskin.twin.field_build import build_field, field_dir
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

STATE = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def spec(layout):
    """A coarse field over both whole faces (10 × 27.5 mm steps: cheap, not accurate)."""
    return FieldSpec(layout, STATE, discretisation=COARSE_FIELD_MESH, spacing_mm=(10.0, 27.5),
                     force_nodes=4, height_nodes=4)


@pytest.fixture(scope="module")
def cache(spec, tmp_path_factory):
    root = tmp_path_factory.mktemp("fields")
    with threadpool_limits(limits=1):
        build_field(spec, root, workers=0, progress=False)
    return root


def _protocol(**kw) -> Protocol:
    base = dict(levels_ml=(0.0,), touch_trials=2, duration_s=3.0, touch_dwells=4,
                dwell_slide_s=0.25, touch_placement="uniform", lifts=True, hover=True,
                approach=True, second_finger=1.0, response="field", stream=1)
    return Protocol(**{**base, **kw})


def test_the_field_reading_is_the_same_for_any_number_of_workers(spec, cache):
    proto = _protocol()
    fields = {STATE: field_dir(spec, cache)}
    a = simulate_experiment(proto, workers=1, progress=False, fields=fields)
    b = simulate_experiment(proto, workers=2, progress=False, fields=fields)
    assert len(a.trials) == 3
    for ta, tb in zip(a.trials, b.trials):
        np.testing.assert_array_equal(ta.capacitance, tb.capacitance)
        np.testing.assert_array_equal(ta.markers, tb.markers, strict=False)
        assert ta.meta == tb.meta
    touch = [t for t in a.trials if t.meta["kind"] == "touch"]
    assert all(t.meta["response_field"] == spec.key() for t in touch)
    # a trial visits its 4 dwell points, slides between them and has a second finger
    assert all(len(t.meta["touch_uv_mm"]) == 4 and "second_finger" in t.meta for t in touch)


def test_the_field_reading_agrees_with_the_solve_reading(spec, cache):
    """The same trials (same plan, same draws) read from the field and solved per dwell
    (TouchResponse, both on the field's mesh): their readouts agree within 15 % of the
    finger's signal in contact (1 % and 9.7 % measured). Catches a field of the wrong state or
    face, or frames or paths out of step (off by the whole signal); both read the same trial
    up to the models' errors, of which the coarse field's interpolation at 10 × 27.5 mm steps
    between the anchors is the larger."""
    proto = _protocol(touch_dwells=2, lifts=False, hover=False)  # (noise: the same draws)
    kw = dict(workers=1, progress=False, discretisation=COARSE_FIELD_MESH)
    field = simulate_experiment(proto, fields={STATE: field_dir(spec, cache)}, **kw)
    solve = simulate_experiment(replace(proto, response="solve"), **kw)
    base = field.trials[0].capacitance.mean(axis=0)
    for tf, ts in zip(field.trials[1:], solve.trials[1:]):
        np.testing.assert_array_equal(tf.force, ts.force)
        on = tf.contact[:, 0]
        signal = np.abs(ts.capacitance[on] - base).max()
        err = np.abs(tf.capacitance[on] - ts.capacitance[on]).max()
        print(f"\n{tf.name}: field vs solve reading {err * 1e3:.2f} fF of {signal * 1e3:.1f} fF")
        assert err < 0.15 * signal, f"{tf.name}: {err * 1e3:.2f} fF of {signal * 1e3:.1f} fF"


def test_fields_are_checked_at_the_door(spec, cache, layout):
    proto = _protocol(touch_trials=1, second_finger=0.0)
    with pytest.raises(EctskinError, match="give the states' response fields"):
        simulate_experiment(proto, workers=1, progress=False)
    with pytest.raises(EctskinError, match="response is 'solve'"):
        simulate_experiment(replace(proto, response="solve"), workers=1, progress=False,
                            fields={STATE: field_dir(spec, cache)})
    with pytest.raises(EctskinError, match="no response field for the inflation state"):
        simulate_experiment(replace(proto, levels_ml=(10.0,)), workers=1, progress=False,
                            fields={STATE: field_dir(spec, cache)})
    with pytest.raises(EctskinError, match="differs from the simulation in \\['eps_r'\\]"):
        simulate_experiment(proto, workers=1, progress=False, eps_r=3.0,
                            fields={STATE: field_dir(spec, cache)})
    with pytest.raises(EctskinError, match="response"):
        Protocol(response="mesh")
    with pytest.raises(EctskinError, match="dwell_slide_s"):
        Protocol(touch_dwells=30, dwell_slide_s=2.0)


def test_an_experiment_of_its_own_stream_shares_no_draw(layout):
    """Stream 0 is the seed's streams as they always were (the paper's protocol unchanged);
    another stream plans and draws otherwise with the same seed (the contact experiment's
    no-contact trial 0 was the paper's trial 0, noise and all)."""
    p0, p1 = Protocol(seed=3), Protocol(seed=3, stream=1)
    np.testing.assert_array_equal(p0.rng(1, 7).random(4), np.random.default_rng([3, 1, 7]).random(4))
    assert not np.array_equal(p1.rng(1, 7).random(4), p0.rng(1, 7).random(4))
    small = dict(levels_ml=(0.0,), touch_trials=1, duration_s=1.0, touch_placement="uniform")
    a = simulate_experiment(Protocol(**small), workers=1, progress=False, trials=["trial_0000"])
    b = simulate_experiment(Protocol(**small, stream=1), workers=1, progress=False,
                            trials=["trial_0000"])
    assert not np.array_equal(a.trials[0].capacitance, b.trials[0].capacitance)
    pa = plan_trials(Protocol(**small), layout)[1]
    pb = plan_trials(Protocol(**small, stream=1), layout)[1]
    assert pa.touch_uv_mm != pb.touch_uv_mm
