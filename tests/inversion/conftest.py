"""Fixtures of the inversion's tests: a flat skin with an analytic forward model in the response
field's interface (``analytic_field``), and a small response field of the twin (``small_field``,
a window of the front face over an inflated chamber, coarse mesh, built once per session).

Wires lie along v on the plane of the skin (u, v); a fingertip is a point at height z above it.
The finger's coupling to wire i is the potential kernel of a straight segment (a line charge
from v = a_i to b_i at u = x_i): k_i = asinh((b_i − v)/ρ_i) − asinh((a_i − v)/ρ_i), with
ρ_i² = (u − x_i)² + z². A grounded conductor brought near a capacitance network lowers each
mutual capacitance by the product of its couplings over its own capacitance (the Schur
complement of the Maxwell matrix), so a pair's signal is ΔC_ij = −α k_i k_j. The fingertip's
centre sits at z = z0 − d F^(2/3) when it presses with F (a Hertzian indentation) and at z0 + h
when it hovers h above the skin. Everything, derivatives included, is closed-form, so the
inversion is tested apart from the twin and its interpolation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from ectskin.twin.field_build import build_field
from ectskin.twin.field_spec import COARSE_FIELD_MESH, FieldSpec

#: wires: (u position, v start, v end) mm
WIRES = ((-15.0, 0.0, 20.0), (-9.0, 0.0, 50.0), (-3.0, 0.0, 35.0), (3.0, 0.0, 60.0),
         (9.0, 0.0, 28.0), (15.0, 0.0, 45.0))
PAIRS = tuple(combinations(range(len(WIRES)), 2))


@dataclass(frozen=True)
class AnalyticSpec:
    inflation_ml: tuple[float, ...] = (0.0,)
    force_range_n: tuple[float, float] = (0.3, 2.0)
    height_range_mm: tuple[float, float] = (0.5, 10.0)
    window: tuple[tuple[float, float], tuple[float, float]] = ((-18.0, 18.0), (2.0, 58.0))
    spacing_mm: float = 2.0

    def extent(self, face: str) -> tuple[tuple[float, float], tuple[float, float]]:
        return self.window


@dataclass
class AnalyticField:
    """The flat skin's readouts for a finger anywhere: the interface of ``ResponseField``."""

    spec: AnalyticSpec = field(default_factory=AnalyticSpec)
    alpha: float = 2e-3  # pF per unit coupling²
    z0_mm: float = 6.0
    indent_mm: float = 1.2  # d: z = z0 − d F^(2/3)
    faces: tuple[str, ...] = ("front",)

    def __post_init__(self) -> None:
        self.n_pairs = len(PAIRS)
        self.untouched = np.array([0.05 + 0.4 / (1 + abs(WIRES[i][0] - WIRES[j][0]) / 6.0)
                                   for i, j in PAIRS])
        self.forces_n = np.linspace(*self.spec.force_range_n, 5)
        lo, hi = np.log(self.spec.height_range_mm)
        self.heights_mm = np.exp(np.linspace(lo, hi, 5))

    def grid(self, face: str) -> tuple[np.ndarray, np.ndarray]:
        (ulo, uhi), (vlo, vhi) = self.spec.extent(face)
        step = self.spec.spacing_mm
        return (np.linspace(ulo, uhi, int(round((uhi - ulo) / step)) + 1),
                np.linspace(vlo, vhi, int(round((vhi - vlo) / step)) + 1))

    def node_values(self, face: str, part: str = "contact") -> np.ndarray:
        u, v = self.grid(face)
        U, V = np.meshgrid(u, v, indexing="ij")
        if part == "contact":
            return self.readout(face, U[..., None], V[..., None], self.forces_n, 0.0)
        return self.readout(face, U[..., None], V[..., None], 0.0, self.heights_mm)

    # ------------------------------------------------------------------ physics
    def _z(self, force_n, height_mm):
        """z and dz/dF, dz/dh."""
        f = np.maximum(force_n, 1e-12)
        contact = height_mm == 0
        z = np.where(contact, self.z0_mm - self.indent_mm * f ** (2 / 3), self.z0_mm + height_mm)
        dz_df = np.where(contact, -self.indent_mm * (2 / 3) * f ** (-1 / 3), 0.0)
        dz_dh = np.where(contact, 0.0, 1.0)
        return z, dz_df, dz_dh

    def _couplings(self, u, v, z):
        """k (..., n_wires) and its derivatives along u, v, z."""
        k, ku, kv, kz = [], [], [], []
        for x, a, b in WIRES:
            rho = np.sqrt((u - x) ** 2 + z**2)
            sb, sa = b - v, a - v
            qb, qa = np.sqrt(rho**2 + sb**2), np.sqrt(rho**2 + sa**2)
            k.append(np.arcsinh(sb / rho) - np.arcsinh(sa / rho))
            dk_drho = -sb / (rho * qb) + sa / (rho * qa)
            ku.append(dk_drho * (u - x) / rho)
            kz.append(dk_drho * z / rho)
            kv.append(-1.0 / qb + 1.0 / qa)
        return (np.stack(k, -1), np.stack(ku, -1), np.stack(kv, -1), np.stack(kz, -1))

    def _parts(self, face, u_mm, v_mm, force_n, height_mm):
        if face not in self.faces:
            raise ValueError(face)
        u, v, f, h = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64)
                                           for a in (u_mm, v_mm, force_n, height_mm)))
        z, dz_df, dz_dh = self._z(f, h)
        return self._couplings(u, v, z), dz_df, dz_dh

    def readout(self, face, u_mm, v_mm, force_n, height_mm=0.0) -> np.ndarray:
        (k, *_), _, _ = self._parts(face, u_mm, v_mm, force_n, height_mm)
        i, j = np.array(PAIRS).T
        return self.untouched - self.alpha * k[..., i] * k[..., j]

    def delta(self, face, u_mm, v_mm, force_n, height_mm=0.0) -> np.ndarray:
        return self.readout(face, u_mm, v_mm, force_n, height_mm) - self.untouched

    def jacobian(self, face, u_mm, v_mm, force_n, height_mm=0.0) -> np.ndarray:
        (k, ku, kv, kz), dz_df, dz_dh = self._parts(face, u_mm, v_mm, force_n, height_mm)
        i, j = np.array(PAIRS).T

        def d(dk):
            return -self.alpha * (dk[..., i] * k[..., j] + k[..., i] * dk[..., j])

        dz = d(kz)
        contact = (np.asarray(height_mm) == 0) & np.ones(dz.shape[:-1], bool)
        out = np.stack([d(ku), d(kv), dz * dz_df[..., None], dz * dz_dh[..., None]], axis=-1)
        out[..., 3] = np.where(contact[..., None], np.nan, out[..., 3])
        out[..., 2] = np.where(contact[..., None], out[..., 2], np.nan)
        return out


@pytest.fixture(scope="session")
def analytic_field() -> AnalyticField:
    return AnalyticField()


@pytest.fixture(scope="session")
def make_analytic_field():
    """AnalyticField with its spec's fields (ranges, window, spacing) given as keywords."""

    def make(**spec) -> AnalyticField:
        return AnalyticField(spec=AnalyticSpec(**spec))

    return make


#: the small field's window: 16 × 20 mm of the front face around the wires at x = ±5 mm, over
#: chamber 2 (inflated), with the ends of the wire at x = −5 (v = 55) inside
SMALL_WINDOW = ((-8.0, 8.0), (40.0, 60.0))


@pytest.fixture(scope="session")
def small_spec(layout) -> FieldSpec:
    return FieldSpec(
        layout, (0.0, 20.0, 0.0), discretisation=COARSE_FIELD_MESH, spacing_mm=(2.0, 2.0),
        faces=("front",), window_mm=SMALL_WINDOW, force_nodes=5, height_nodes=4,
        height_range_mm=(1.0, 8.0),
    )


@pytest.fixture(scope="session")
def small_field(small_spec, tmp_path_factory):
    """About 10-20 s to build (one BLAS thread, as the field's solves)."""
    with threadpool_limits(limits=1):
        return build_field(small_spec, tmp_path_factory.mktemp("fields"), workers=0,
                           progress=False)
