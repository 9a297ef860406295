"""The second finger pressing while the first is above the skin, read from a response field,
against direct two-finger solves (ectskin.twin.field_response, issue 19).

The two fingers are one grounded conductor: the first, above the skin, still screens the second,
by up to about the second finger's whole signal with the first low down and by a few per cent
with it 100 mm up. :class:`FieldTouchResponse` takes the correction from two-finger solves at a
few of the first finger's heights (Chebyshev-Lobatto in ln(h + 10 mm) over those frames'). Here
the first finger lifts through a trial's whole range (0.5 mm to the approach's 100 mm) while the
second presses with a force that wanders and a point that rolls; every frame is compared with a
direct ``SensorModel.capacitance`` two-finger solve of the field's own sensor (the same coarse
mesh: the bound measures the approximation, not the mesh), in a state without and one with every
chamber inflated. Errors are fractions of the second finger's signal |C₂ − C_untouched| (largest
over the pairs), printed with ``pytest -s`` for BENCHMARKS.md.
"""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.twin import Touch
from ectskin.twin.field_build import build_field
from ectskin.twin.field_response import FieldTouchResponse, contact_delta
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec
from ectskin.twin.finger import Finger
from ectskin.twin.human import FingerPath
from ectskin.twin.mechanics import Handling

WINDOW = ((-21.0, 6.0), (50.0, 56.0))
CENTRE = (3.0, 53.0)
SECOND = (-19.0, 53.5)  # the protocol's separation (22 mm) from the first finger along u
REGION = ((-5.0, 50.5), (5.0, 55.5))
#: the readout's error while the second finger presses alone, of the second finger's signal
#: (measured 2.6-4.1 %; the correction at the median height is off by 60-78 %)
BOUND = 0.05


@pytest.fixture(autouse=True, scope="module")
def _blas_one_thread():
    with threadpool_limits(limits=1):
        yield


@pytest.fixture(scope="module", params=[(0.0, 0.0, 0.0), (20.0, 20.0, 20.0)], ids=["0-0-0", "20-20-20"])
def field(request, layout, tmp_path_factory):
    spec = FieldSpec(
        layout, request.param, discretisation=COARSE_FIELD_MESH, spacing_mm=(2.0, 2.0),
        faces=("front",), window_mm=WINDOW, force_nodes=5, height_nodes=5,
        height_range_mm=(0.5, 15.0),
    )
    return build_field(spec, tmp_path_factory.mktemp("fields"), workers=0, progress=False)


def _paths(h_above: np.ndarray) -> tuple[FingerPath, FingerPath]:
    """The first finger pressing for 3 frames, then above the skin at ``h_above``; the second
    pressing from the 3rd frame on, its force wandering 0.6-1.6 N, its point rolling ±0.2 mm."""
    n = 3 + h_above.size
    k = np.arange(n)
    h1 = np.r_[np.zeros(3), h_above]
    on1 = h1 == 0
    uv1 = np.tile(CENTRE, (n, 1)) + np.c_[0.3 * np.sin(k), 0.2 * np.cos(k)]
    f1 = np.where(on1, np.linspace(0.8, 1.4, n), 0.0)
    first = FingerPath(on1, uv1, f1, h1, f1[:, None] * np.array([0.1, 0.1]))
    on2 = k >= 2
    f2 = np.where(on2, 1.1 + 0.5 * np.sin(0.7 * k), 0.0)
    uv2 = np.where(on2[:, None], np.tile(SECOND, (n, 1)) + np.c_[0.2 * np.cos(k), 0.2 * np.sin(k)], np.nan)
    second = FingerPath(on2, uv2, f2, np.where(on2, 0.0, np.nan), f2[:, None] * np.array([0.1, -0.1]))
    return first, second


def _direct(sensor, state, first: FingerPath, second: FingerPath, frames, first_height=None):
    """(n, P) direct two-finger solves of ``frames`` (the first at its height, or at
    ``first_height`` mm: far enough, the second finger alone)."""
    out = []
    for i in frames:
        h = first.height_mm[i] if first_height is None else first_height
        touches = (Touch("front", tuple(first.uv_mm[i])), Touch("front", tuple(second.uv_mm[i])))
        shear = np.stack([first.shear_n[i], second.shear_n[i]])[None]
        out.append(sensor.capacitance(state, touches, np.array([[0.0, second.force_n[i]]]),
                                      Handling(shear_n=shear), heights_mm=np.array([[h, 0.0]]))[0])
    return np.stack(out)


def _model(field, sensor, first, second):
    return FieldTouchResponse(field, sensor, field.spec.inflation_ml, "front", first,
                              Handling(), None, REGION, "front", second)


@pytest.mark.parametrize("finger", [None, Finger(radius_mm=10.0, pulp_modulus_mpa=0.05)],
                         ids=["field_finger", "R10_E0.05"])
def test_the_screening_follows_the_first_fingers_height(field, finger):
    """The first finger at 0.5-100 mm over the frames in which the second presses alone: within
    BOUND of the second finger's signal at every frame (the anchors' 4 heights included, the
    frames between them off the anchors). The correction read at the median height for every
    frame (the first finger's screening frozen there) is off by more than 6 times BOUND."""
    state = field.spec.inflation_ml
    sensor = field.spec.sensor()
    if finger is not None:  # another person's second finger
        sensor = sensor.with_fingers(sensor.finger, finger)
    h_above = np.geomspace(0.5, 100.0, 13)
    first, second = _paths(h_above)
    m = _model(field, sensor, first, second)
    got = m(first, Handling(), second)
    alone = np.flatnonzero(second.contact & ~first.contact)
    direct = _direct(sensor, state, first, second, alone)
    signal = np.abs(_direct(sensor, state, first, second, alone, 1e5) - field.untouched).max(axis=1)
    err = np.abs(got[alone] - direct).max(axis=1)
    rel = float((err / signal).max())
    # the screening frozen at the median height: one two-finger solve there at the frames' mean
    # points and force, read at every height (the correction this replaced)
    h_med = float(np.median(first.height_mm[alone]))
    uv1, uv2 = first.uv_mm[alone].mean(axis=0), second.uv_mm[alone].mean(axis=0)
    f2, sh2 = float(second.force_n[alone].mean()), second.shear_n[alone].mean(axis=0)
    at_med = sensor.capacitance(
        state, (Touch("front", tuple(uv1)), Touch("front", tuple(uv2))), np.array([[0.0, f2]]),
        Handling(shear_n=np.stack([np.zeros(2), sh2])[None]), heights_mm=np.array([[h_med, 0.0]]),
    )[0]
    frozen_corr = (at_med - field.untouched - contact_delta(field, "front", uv2[0], uv2[1], f2)[0]
                   - m.finger_above(uv1[None], np.array([h_med]))[0])
    frozen = got[alone] - m.second_alone(first.height_mm[alone]) + frozen_corr
    rel_frozen = float((np.abs(frozen - direct).max(axis=1) / signal).max())
    print(f"\n{state} ml, second finger {'R10' if finger else 'field'}'s, the first at 0.5-100 mm: "
          f"{err.max() * 1e3:.2f} fF, {rel:.2%} of its signal ({signal.min() * 1e3:.1f}-"
          f"{signal.max() * 1e3:.1f} fF); frozen at {h_med:.1f} mm: "
          f"{np.abs(frozen - direct).max() * 1e3:.1f} fF, {rel_frozen:.1%}")
    assert rel < BOUND
    assert rel_frozen > 6 * BOUND
    x = m.screen[0]  # the anchors: 4 heights, the frames' lowest and highest among them
    node_h = np.exp(x) - m.screen_scale_mm
    np.testing.assert_allclose(node_h[[0, -1]], [0.5, 100.0], rtol=1e-9)
    assert x.size == 4 and np.min(np.abs(h_above[1:-1, None] - node_h[None, 1:-1])) > 0.5


def test_one_height_one_anchor_and_heights_outside_refused(field):
    """A first finger lifted to one height (a lift) takes one two-finger solve, exact at that
    height up to the second finger's force and roll (within 1.5 % of its signal); the model
    refuses heights beyond its anchors, and a second finger that never presses alone."""
    state = field.spec.inflation_ml
    sensor = field.spec.sensor()
    first, second = _paths(np.full(6, 25.0))
    m = _model(field, sensor, first, second)
    alone = np.flatnonzero(second.contact & ~first.contact)
    direct = _direct(sensor, state, first, second, alone)
    signal = np.abs(_direct(sensor, state, first, second, alone, 1e5) - field.untouched).max(axis=1)
    rel = float((np.abs(m(first, Handling(), second)[alone] - direct).max(axis=1) / signal).max())
    print(f"\n{state} ml, the first lifted to 25 mm: {rel:.2%} of the second finger's signal")
    assert m.screen[0].size == 1 and rel < 0.015
    with pytest.raises(EctskinError, match="anchors span 25-25 mm"):
        m.second_alone(np.array([30.0]))
    pressing, both_on = _paths(np.zeros(0))  # the first presses whenever the second does
    with pytest.raises(EctskinError, match="never does"):
        _model(field, sensor, pressing, both_on).second_alone(np.array([1.0]))
