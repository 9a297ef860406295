"""The response field against the twin's ground truth, direct ``SensorModel.capacitance`` solves.

One small field (a 4 × 4 mm window of the front face, over an inflated chamber, 1 mm steps, a
coarse discretisation) is built once; its nodes must be the direct solves, and at random points
between the nodes it must stay within the acceptance bound of ``docs/field.md``: 0.5 fF and 2 %
of the finger's signal |C_touch − C_untouched|, per pair.
"""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.twin import Touch
from ectskin.twin.field import JACOBIAN_AXES, ResponseField
from ectskin.twin.field_build import build_field, load_field
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

#: the acceptance bound: absolute (pF) and relative to the finger's signal, per pair
ABS_PF = 0.5e-3
REL = 0.02

COARSE = COARSE_FIELD_MESH
WINDOW = ((-1.0, 3.0), (52.0, 56.0))


@pytest.fixture(autouse=True, scope="module")
def _blas_one_thread():
    """BLAS on one thread, as the field's solves (also the fast choice on 2 shared cores)."""
    with threadpool_limits(limits=1):
        yield


@pytest.fixture(scope="module")
def spec(layout):
    return FieldSpec(
        layout, (0.0, 20.0, 0.0), discretisation=COARSE, spacing_mm=(1.0, 1.0), faces=("front",),
        window_mm=WINDOW, force_nodes=6, height_nodes=5, height_range_mm=(1.0, 8.0),
    )


@pytest.fixture(scope="module")
def field(spec, tmp_path_factory):
    return build_field(spec, tmp_path_factory.mktemp("fields"), workers=0, progress=False)


@pytest.fixture(scope="module")
def sensor(spec):
    return spec.sensor()


def test_nodes_are_the_direct_solves(spec, field, sensor):
    """Contact nodes are the twin's solves and the untouched readout is the state's (both
    exactly); hover nodes (the Schur path) equal the direct solves to round-off."""
    u, v = spec.grid("front")
    np.testing.assert_array_equal(field.untouched, sensor.capacitance(spec.inflation_ml)[0])
    for iu, iv in [(0, 0), (2, 3), (4, 1)]:
        touch = Touch("front", (float(u[iu]), float(v[iv])))
        direct = sensor.capacitance(spec.inflation_ml, touch, spec.forces())
        np.testing.assert_array_equal(field.node_values("front")[iu, iv], direct)
        hs = spec.heights()
        hover = sensor.capacitance(spec.inflation_ml, touch, np.zeros(hs.size), heights_mm=hs)
        np.testing.assert_allclose(field.node_values("front", "hover")[iu, iv], hover,
                                   rtol=1e-10, atol=0)
        # the interpolant passes through its nodes
        np.testing.assert_allclose(
            field.readout("front", u[iu], v[iv], spec.forces()), direct, rtol=1e-12, atol=1e-15
        )
        np.testing.assert_allclose(
            field.readout("front", u[iu], v[iv], 0.0, hs), hover, rtol=1e-12, atol=1e-15
        )


def test_between_the_nodes_the_field_meets_the_acceptance_bound(spec, field, sensor):
    rng = np.random.default_rng(7)
    (ulo, uhi), (vlo, vhi) = WINDOW
    worst = []
    for k in range(16):
        u, v = rng.uniform(ulo, uhi), rng.uniform(vlo, vhi)
        touch = Touch("front", (u, v))
        if k % 2:
            h = float(np.exp(rng.uniform(*np.log(spec.height_range_mm))))
            direct = sensor.capacitance(spec.inflation_ml, touch, [0.0], heights_mm=[h])[0]
            got = field.readout("front", u, v, 0.0, h)
        else:
            f = rng.uniform(*spec.force_range_n)
            direct = sensor.capacitance(spec.inflation_ml, touch, [f])[0]
            got = field.readout("front", u, v, f)
        err = np.abs(got - direct)
        signal = np.abs(direct - field.untouched)
        worst.append((err.max(), (err / signal).max()))
        assert np.all(err <= ABS_PF), f"{touch}: error {err.max() * 1e3:.3f} fF > 0.5 fF"
        assert np.all(err <= REL * signal), (
            f"{touch}: error {(err / signal).max():.2%} of the finger's signal > 2 %"
        )
    # the points are off the nodes: the field is not just echoing its nodes
    assert max(w[0] for w in worst) > 1e-6 * 1e-3


def test_jacobian_is_the_derivative_of_the_readout(field):
    u = np.array([0.3, 1.7, 2.9])
    v = np.array([52.4, 54.1, 55.6])
    f = np.array([0.5, 1.1, 1.9])
    J = field.jacobian("front", u, v, f)
    assert J.shape == (3, field.n_pairs, 4)
    assert np.all(np.isnan(J[..., 3])) and np.all(np.isfinite(J[..., :3]))
    step = 1e-5
    for col, (du, dv, df) in enumerate([(step, 0, 0), (0, step, 0), (0, 0, step)]):
        fd = (field.readout("front", u + du, v + dv, f + df)
              - field.readout("front", u - du, v - dv, f - df)) / (2 * step)
        np.testing.assert_allclose(J[..., col], fd, rtol=1e-5, atol=1e-9)
    h = np.array([1.3, 2.5, 7.0])
    Jh = field.jacobian("front", u, v, 0.0, h)
    assert np.all(np.isnan(Jh[..., 2])) and np.all(np.isfinite(Jh[..., [0, 1, 3]]))
    fd = (field.readout("front", u, v, 0.0, h + step) - field.readout("front", u, v, 0.0, h - step))
    np.testing.assert_allclose(Jh[..., 3], fd / (2 * step), rtol=1e-5, atol=1e-9)
    fd = (field.readout("front", u + step, v, 0.0, h) - field.readout("front", u - step, v, 0.0, h))
    np.testing.assert_allclose(Jh[..., 0], fd / (2 * step), rtol=1e-5, atol=1e-9)
    assert JACOBIAN_AXES == ("u_mm", "v_mm", "force_n", "height_mm")


def test_jacobian_follows_the_direct_solves(spec, field, sensor):
    """The field's slopes are the physics' slopes: central differences of direct solves over
    ±0.5 mm and ±0.2 N agree to within a quarter of the largest slope (an interpolant's slopes
    are less accurate than its values, and the differences smooth over ±0.2 N too; a wrong
    axis, sign or unit is off by the whole slope)."""
    p, u, v, f = spec.inflation_ml, 1.4, 53.6, 1.0
    J = field.jacobian("front", u, v, f)

    def solve(du=0.0, dv=0.0, df=0.0):
        return sensor.capacitance(p, Touch("front", (u + du, v + dv)), [f + df])[0]

    for col, d, (du, dv, df) in [(0, 0.5, (1, 0, 0)), (1, 0.5, (0, 1, 0)), (2, 0.2, (0, 0, 1))]:
        fd = (solve(d * du, d * dv, d * df) - solve(-d * du, -d * dv, -d * df)) / (2 * d)
        assert np.abs(J[:, col] - fd).max() <= 0.25 * np.abs(fd).max(), JACOBIAN_AXES[col]


def test_vectorised_queries_and_delta(field):
    u = np.linspace(-1.0, 3.0, 6).reshape(2, 3)
    out = field.readout("front", u, 54.0, 1.2)
    assert out.shape == (2, 3, field.n_pairs)
    one = np.stack([field.readout("front", x, 54.0, 1.2) for x in u.ravel()]).reshape(out.shape)
    np.testing.assert_allclose(out, one, rtol=1e-13)
    mixed = field.readout("front", [0.0, 0.0], 54.0, [1.2, 0.0], [0.0, 2.0])
    np.testing.assert_allclose(mixed[0], field.readout("front", 0.0, 54.0, 1.2), rtol=1e-13)
    np.testing.assert_allclose(mixed[1], field.readout("front", 0.0, 54.0, 0.0, 2.0), rtol=1e-13)
    np.testing.assert_allclose(
        field.delta("front", u, 54.0, 1.2), out - field.untouched, rtol=1e-13
    )


@pytest.mark.parametrize(
    "args, match",
    [
        (("back", 0.0, 54.0, 1.0), "unknown face"),
        (("front", 3.5, 54.0, 1.0), "u_mm"),
        (("front", 0.0, 51.0, 1.0), "v_mm"),
        (("front", 0.0, 54.0, 2.5), "force_n"),
        (("front", 0.0, 54.0, 1.0, 2.0), "force_n 0"),
        (("front", 0.0, 54.0, 0.0, 9.0), "height_mm"),
        (("front", 0.0, 54.0, 0.0, -1.0), ">= 0"),
        (("front", np.nan, 54.0, 1.0), "NaN"),
        (("front", [0.0, 1.0], [54.0, 54.0, 55.0], 1.0), "broadcast"),
    ],
)
def test_queries_off_the_field_are_refused(field, args, match):
    with pytest.raises(EctskinError, match=match):
        field.readout(*args)


def test_the_file_alone_rebuilds_the_field(field, tmp_path):
    path = field.save(tmp_path / "f.npz")
    again = load_field(path)
    assert again.key == field.key and again.spec.key() == field.spec.key()
    np.testing.assert_array_equal(again.node_values("front"), field.node_values("front"))
    np.testing.assert_array_equal(
        again.readout("front", 1.3, 53.3, 0.7), field.readout("front", 1.3, 53.3, 0.7)
    )
    with pytest.raises(EctskinError, match="not found"):
        ResponseField.from_file(tmp_path / "missing.npz")
