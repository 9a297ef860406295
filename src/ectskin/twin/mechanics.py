"""Mechanics of the 3-chamber pneumatic manipulator: inflation bulges, touch bending, dimples.

The body is a 50 (x) × 120 (z) × 20 (y) mm block clamped at z = 0 (DESIGN.md). A point of the body
surface is addressed by ``(surface, u, v)`` (see :mod:`ectskin.layout.layout`); :meth:`Manipulator.deform`
maps rest surface coordinates to the deformed 3D position, frame by frame. Material points keep
their (u, v): wires drawn on a face stretch with it, which is how electrode length and width follow
the local surface strain.

The deformation is composed of four parts (each documented where it is computed):

1. **Axial extension** of each inflated chamber's span (small, ``axial_strain_per_ml``).
2. **Face bulge** over each chamber footprint, both faces, shape b(x, z) = h_k φ(x) ψ_k(z) with
   φ(x) = 1 − |2x/w|ⁿ across the chamber (n = ``bulge_profile_exponent``: n = 2 is a membrane's
   parabola, a large n a face that rises nearly flat, like a piston, and turns down at the side
   walls) and ψ_k a raised-cosine window along it. The e-skin and the face wall limit stretch
   along z: a fraction κ (``face_axial_inextensibility``) of the arc length the bulge adds along
   z is taken back by pulling material in towards the base (κ = 0: points move only along the
   normal and wires stretch fully; κ = 1: face arc length along z is conserved; solved exactly,
   see ``_face_pull_in``). The bulge height h_k follows from volume conservation: the injected
   volume fills the two face bulges (2 · h · A · n/(2(n + 1)) for this shape, A the chamber
   footprint) and the compliance of the rest of the chamber (``wall_compliance`` · pressure),
   with a membrane pressure that stiffens with stretch, P(h) = k_f · h · (1 + (h/h_s)²).
3. **Dimple** under each finger: a Gaussian indentation of depth F / k_d, k_d rising with the local
   chamber pressure; the dimples of several fingers on one face add (superposition, small
   indentations).
4. **Bending and twist** by the finger and the experimenter's hand (manual handling): the body
   is a clamped Kirchhoff rod (:mod:`ectskin.twin.rod`) with section stiffnesses EI_x, EI_y and
   GJ from a silicone modulus and the chambered cross-section (hollow over each chamber's span,
   solid between, :meth:`Manipulator.section_stiffness`), rising with chamber pressure. Loads are
   the finger's normal force and its tangential (friction-limited) push on the face, and the
   hand's push at another material point; off-centre and off-axis loads twist the body and bend
   it both ways, with large rotations. A face point at section offset (x, y') moves to
   r(s) + R(s)·(x, y', 0).

A finger presses its face along the face's normal as the body carries it
(:meth:`Manipulator.face_frame`: the section frame at the point; the bulges and dimples do not
turn the finger); :meth:`Manipulator.deform` also maps one set of points per frame, which the
sensor uses to find the skin under a fingertip whose pad grows with the force.

Several fingers: wherever a ``touch`` is taken, it may be one :class:`Touch` (the forces are then
one per frame, shape (F,)) or a tuple of them (forces (F, T), one column per touch, or (T,) for
one frame). Each finger dents its face and loads the rod with its own normal force (and shear,
``Handling.shear_n``); the single-touch path computes exactly what it computed before tuples were
accepted.

Units: mm, ml (= 1000 mm³), N, kPa (= 1e-3 N/mm²).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from scipy.optimize import brentq

from ectskin._check import EctskinError
from ectskin.twin.mechanics_tables import (
    POSE_FRAMES_KEPT,
    POSES_KEPT,
    RowLookup,
    axis_table,
    bredt_torsion,
    invert_pull_in,
    pose_key,
    pull_in_table,
    rect_torsion,
    remember,
)
from ectskin.twin.rod import PointLoad
from ectskin.twin.rod import solve as solve_rod
from ectskin.twin.surface_map import SurfaceMap

SIDE = {"front": 1.0, "back": -1.0}
#: rows (values of φ) of the face's arc-length table (:meth:`Manipulator._face_pull_in`)
_PULL_IN_PHIS = 41


@dataclass(frozen=True)
class ManipulatorConfig:
    """Geometry and material parameters. **(assumed)** values are documented defaults."""

    width_mm: float = 50.0
    length_mm: float = 120.0
    thickness_mm: float = 20.0  # (assumed)
    chamber_centres_z_mm: tuple[float, ...] = (20.0, 60.0, 100.0)  # (assumed placement)
    chamber_size_x_mm: float = 40.0
    chamber_size_z_mm: float = 30.0
    max_volume_ml: float = 30.0  # (assumed) beyond this a chamber would burst
    chamber_wall_mm: float = 4.0  # (assumed) silicone between each face and a chamber's cavity
    # inflation: membrane pressure P(h) = k_f h (1 + (h/h_s)^2) [kPa], wall compliance [ml/kPa]
    face_stiffness_kpa_per_mm: float = 1.0  # (assumed; calibrated with wall_compliance)
    stiffening_height_mm: float = 6.0  # (assumed)
    wall_compliance_ml_per_kpa: float = 0.1  # (assumed; calibrated to the paper's ~40 %)
    face_axial_inextensibility: float = 0.8  # (assumed; calibrated: cross-face pairs fall)
    # φ(x) = 1 − |2x/w|^n across the chamber. (assumed; calibrated with face_axial_inextensibility
    # so that every cross-face pair falls and every same-face pair rises, paper §2.2: the face
    # wall carrying the e-skin laminate rises nearly flat; with n = 2, a membrane's parabola,
    # the diagonal cross-face pairs rise instead)
    bulge_profile_exponent: float = 8.0
    axial_strain_per_ml: float = 0.0  # (assumed) chamber span elongation per ml (off)
    # bending and twist: section stiffness from the modulus and the chambered cross-section,
    # times (1 + pressure_stiffening · P(z)/kPa) where a chamber spans z
    # (assumed: Dragon Skin 30, 100 % modulus 0.59 MPa (Smooth-On datasheet), neo-Hookean
    # E = 0.59 / 0.58 ≈ 1.0 MPa; incompressible, so G = E / 3)
    modulus_mpa: float = 1.0
    pressure_stiffening_per_kpa: float = 0.05  # (assumed)
    # dimple: depth = F / (k_d0 (1 + dimple_stiffening * P_local))
    dimple_stiffness_n_per_mm: float = 1.0  # (assumed)
    dimple_stiffening_per_kpa: float = 0.05  # (assumed)
    dimple_sigma_mm: float = 9.0  # (assumed) Gaussian width of the indentation
    rod_tol_mm: float = 0.01  # the rod's fixed point stops when the tip moves less than this
    beam_points: int = 61  # axial grid of the rod (2 mm steps; tip error < 1e-3 of its deflection)

    @property
    def n_chambers(self) -> int:
        return len(self.chamber_centres_z_mm)



def recording_manipulator(meta: Mapping[str, Any]) -> tuple[ManipulatorConfig, str]:
    """The manipulator a recording was made on, and where it came from.

    ``meta["manipulator"]`` (the twin writes its :class:`ManipulatorConfig` there) → ``(config,
    "recording")``; a recording without one (an import from other hardware) → the default
    (paper's) body, ``(ManipulatorConfig(), "default")``, so that a caller can say which it used.
    A field that :class:`ManipulatorConfig` does not have is an error naming it.
    """
    given = meta.get("manipulator")
    if given is None:
        return ManipulatorConfig(), "default"
    if not isinstance(given, Mapping):
        raise EctskinError(
            f"recording meta 'manipulator': expected a mapping of ManipulatorConfig fields, "
            f"got {type(given).__name__}"
        )
    known = {f.name for f in fields(ManipulatorConfig)}
    unknown = sorted(set(given) - known)
    if unknown:
        raise EctskinError(
            f"recording meta 'manipulator': unknown field(s) {unknown}; expected some of "
            f"{sorted(known)}"
        )
    return ManipulatorConfig(**given), "recording"

@dataclass(frozen=True)
class Touch:
    """A finger touching ``surface`` at rest surface coordinates ``uv_mm`` (mm)."""

    surface: str
    uv_mm: tuple[float, float]


def touch_loads(force_n, touch) -> tuple[tuple[Touch, ...], np.ndarray]:
    """The touches of ``touch`` and their normal forces as an (F, T) array (N).

    ``touch`` None: no touch, ``force_n`` (F,) only counts the frames (T = 0). One
    :class:`Touch`: ``force_n`` a scalar or (F,). A tuple of T touches: ``force_n`` (F, T), or
    (T,) for one frame.
    """
    f = np.asarray(force_n, dtype=np.float64)
    if touch is None or isinstance(touch, Touch):
        f = np.atleast_1d(f)
        if f.ndim != 1:
            raise EctskinError(
                f"touch force: one touch takes one force per frame (F,), got shape {f.shape}"
            )
        return (() if touch is None else (touch,)), f.reshape(-1, 1)[:, : int(touch is not None)]
    touches = tuple(touch)
    if not touches or not all(isinstance(t, Touch) for t in touches):
        raise EctskinError(
            f"touch must be None, a Touch or a non-empty tuple of Touch, got {touch!r:.80}"
        )
    if f.ndim == 1:
        f = f[None]
    if f.ndim != 2 or f.shape[1] != len(touches):
        raise EctskinError(
            f"touch force: {len(touches)} touches take forces of shape (F, {len(touches)}) "
            f"(one column per touch), got shape {np.shape(force_n)}"
        )
    return touches, f


@dataclass(frozen=True)
class Handling:
    """Loads beyond the finger's normal force, per frame (F frames): manual handling.

    ``shear_n`` (F, 2): the finger's tangential force on its face along the face's (x, z) axes,
    N (the finger pushes off-axis); with several touches (F, 2) is the first finger's and
    (F, T, 2) gives one per touch. ``push`` and ``push_force_n`` (F, 3): where the
    experimenter's hand pushes (a surface point) and its force in world axes, N.
    """

    shear_n: np.ndarray | None = None
    push: Touch | None = None
    push_force_n: np.ndarray | None = None

    def n_frames(self) -> int | None:
        for a in (self.shear_n, self.push_force_n):
            if a is not None:
                return int(np.shape(a)[0])
        return None


class Manipulator:
    """Deformation map of the manipulator surface; see the module docstring for the model."""

    def __init__(self, config: ManipulatorConfig | None = None):
        self.config = config or ManipulatorConfig()
        c = self.config
        if not c.bulge_profile_exponent >= 1.0:
            raise EctskinError(
                f"manipulator: bulge_profile_exponent must be >= 1 (2 = parabola), got "
                f"{c.bulge_profile_exponent!r}"
            )
        self._zgrid = np.linspace(0.0, c.length_mm, c.beam_points)
        self._poses: dict = {}  # the last few rod solutions: one state is deformed many times
        # per inflation state (by its bytes), the last few: the bulge heights (a root per
        # chamber) and the pull-in's arc-length table (a placement maps a state a dozen times)
        self._heights: dict[bytes, np.ndarray] = {}
        self._arcs: dict[bytes, tuple[np.ndarray, RowLookup | None]] = {}
        self._rests: dict[tuple, tuple[np.ndarray, ...]] = {}  # deform(keep_rest=True)
        self._dimple_k: dict[tuple, float] = {}  # per state and v: the dimple's stiffness

    # ------------------------------------------------------------------ inflation
    def check_inflation(self, inflation_ml) -> np.ndarray:
        """Validate an inflation vector p (ml per chamber); return it as a float array."""
        c = self.config
        try:
            p = np.asarray(inflation_ml, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise EctskinError(f"inflation must be {c.n_chambers} numbers (ml), got {inflation_ml!r}") from None
        if p.size != c.n_chambers:
            raise EctskinError(
                f"inflation must give one volume per chamber ({c.n_chambers}), got {p.size}: "
                f"{p.tolist()}"
            )
        bad = ~np.isfinite(p) | (p < 0) | (p > c.max_volume_ml)
        if bad.any():
            k = int(np.argmax(bad))
            raise EctskinError(
                f"impossible inflation for chamber {k + 1}: {p[k]} ml; expected 0 to "
                f"{c.max_volume_ml} ml (the chamber's limit)"
            )
        return p

    def bulge_height_mm(self, inflation_ml) -> np.ndarray:
        """(n_chambers,) bulge height h of each face over each chamber (mm).

        Volume conservation: V = 2 · h · A·f + C_w · P(h), with A the chamber footprint and
        f = n / (2(n + 1)) the volume factor of the bulge shape (∫(1 − |2x/w|ⁿ)dx = w·n/(n + 1),
        ∫cos² over l = l/2; f = 1/3 for the parabola).
        """
        p = self.check_inflation(inflation_ml)
        key = p.tobytes()
        if key in self._heights:
            return self._heights[key].copy()
        c = self.config
        n = c.bulge_profile_exponent
        a4 = c.chamber_size_x_mm * c.chamber_size_z_mm * n / (2.0 * (n + 1.0))
        out = np.zeros_like(p)
        for k, v_ml in enumerate(p):
            if v_ml <= 0:
                continue
            v = v_ml * 1000.0  # mm^3

            def residual(h: float, v: float = v) -> float:
                return 2.0 * h * a4 + 1000.0 * c.wall_compliance_ml_per_kpa * self._pressure(h) - v

            out[k] = brentq(residual, 0.0, v / (2.0 * a4))
        remember(self._heights, key, out.copy())
        return out

    def _pressure(self, h):
        """Membrane pressure (kPa) at bulge height h (mm): stiffens with stretch."""
        c = self.config
        return c.face_stiffness_kpa_per_mm * h * (1.0 + (h / c.stiffening_height_mm) ** 2)

    def pressure_kpa(self, inflation_ml) -> np.ndarray:
        """(n_chambers,) chamber pressures (kPa) at an inflation state."""
        return self._pressure(self.bulge_height_mm(inflation_ml))

    def _chamber_window_z(self, z: np.ndarray) -> np.ndarray:
        """(n_chambers, *z.shape) raised-cosine window ψ_k(z) of each chamber's span."""
        c = self.config
        zc = np.asarray(c.chamber_centres_z_mm)[:, None]
        s = (np.reshape(z, (1, -1)) - zc) / c.chamber_size_z_mm
        inside = np.abs(s) < 0.5
        w = np.zeros(s.shape)
        w[inside] = np.cos(np.pi * s[inside]) ** 2  # (only where a chamber spans z)
        return w.reshape((len(c.chamber_centres_z_mm),) + np.shape(z))

    def _window_x(self, x: np.ndarray) -> np.ndarray:
        """φ(x) = 1 − |2x/w|ⁿ across the chambers, 0 beyond their side walls."""
        s = np.asarray(x, dtype=np.float64) / self.config.chamber_size_x_mm
        inside = np.abs(s) < 0.5
        out = np.zeros(s.shape)
        out[inside] = 1.0 - np.abs(2.0 * s[inside]) ** self.config.bulge_profile_exponent
        return out

    def _face_pull_in(
        self, x: np.ndarray, z: np.ndarray, heights: np.ndarray, phi: np.ndarray | None = None
    ) -> np.ndarray:
        """Axial pull-in z − ζ(x, z) of face points (mm) under the bulge.

        With S(ζ) = ∫_0^ζ √(1 + (∂b/∂z')²) dz' the arc length of the bulged face along z
        (∂b/∂z = φ(x) Σ h_k ψ_k'(z)), the material point at rest position z moves to the axial
        position ζ that solves κ S(ζ) + (1 − κ) ζ = z: κ = 1 conserves the face's arc length
        (pure pull-in), κ = 0 moves points only along the normal (ζ = z, full stretch). The local
        stretch along z is s / (κ s + 1 − κ) with s = √(1 + b'²) ≥ 1, so material never
        shortens. S depends on x only through φ(x): it is tabulated over φ and interpolated.
        ``phi``: φ(x), if the caller has it.
        """
        return self._pull_in(x, z, self._arc_table(heights), phi)

    def _arc_table(self, heights: np.ndarray) -> tuple[np.ndarray, RowLookup | None] | None:
        """:meth:`_face_pull_in`'s table of the bulge ``heights`` (kept for the last few
        states); None where nothing pulls in."""
        kappa = self.config.face_axial_inextensibility
        if kappa == 0 or not np.any(heights):
            return None
        zg = self._zgrid
        key = np.asarray(heights, dtype=np.float64).tobytes()
        table = self._arcs.get(key)
        if table is None:
            slope = np.gradient(np.tensordot(heights, self._chamber_window_z(zg), axes=1), zg)
            table = pull_in_table(slope, zg, kappa, _PULL_IN_PHIS)
            remember(self._arcs, key, table)
        return table

    def _pull_in(self, x, z, table, phi=None) -> np.ndarray:
        """:meth:`_face_pull_in` by its :meth:`_arc_table` ``table``."""
        if table is None:
            return np.zeros(np.shape(x))
        zz = np.ravel(z).astype(np.float64)
        phi = np.ravel(self._window_x(x) if phi is None else phi)
        return (zz - invert_pull_in(zz, phi, table, self._zgrid)).reshape(np.shape(x))

    def bulge_mm(self, x, z, heights) -> np.ndarray:
        """Outward bulge b(x, z) = Σ_k h_k φ(x) ψ_k(z) of a front/back face point (mm)."""
        return self._window_x(x) * np.tensordot(heights, self._chamber_window_z(z), axes=1)

    def axial_position(self, z, inflation_ml) -> np.ndarray:
        """Stretched axial position z_s(z): each chamber span elongates by ε_k = a · p_k.

        z_s = z + Σ_k ε_k · clip(z − z_k + l/2, 0, l) (uniform strain over the span).
        """
        c = self.config
        p = np.asarray(inflation_ml, dtype=np.float64)
        z = np.asarray(z, dtype=np.float64)
        out = z.copy()
        if c.axial_strain_per_ml == 0:  # (every term below is +0)
            return out
        for zc, pk in zip(c.chamber_centres_z_mm, p):
            lo = zc - c.chamber_size_z_mm / 2
            out = out + c.axial_strain_per_ml * pk * np.clip(z - lo, 0.0, c.chamber_size_z_mm)
        return out

    # ------------------------------------------------------------------ bending
    def section_stiffness(self, z, inflation_ml) -> np.ndarray:
        """(n, 3) (EI_x, EI_y, GJ) in N·mm² at axial positions z.

        EI_x bends the body towards the faces (about the section's x axis), EI_y sideways, GJ
        twists it. Over a chamber's span the section is a hollow rectangle (the cavity
        ``chamber_size_x`` × (thickness − 2 ``chamber_wall``)), between chambers it is solid;
        the transition follows the chamber window ψ(z). Torsion: Bredt's thin-walled tube for
        the hollow section, Saint-Venant's rectangle (with its series for β) for the solid one.
        Pressure stiffens a chamber's span by (1 + ``pressure_stiffening_per_kpa`` · P).
        """
        c = self.config
        e = c.modulus_mpa  # N/mm²
        g = e / 3.0
        w, t = c.width_mm, c.thickness_mm
        cw, ct = c.chamber_size_x_mm, t - 2.0 * c.chamber_wall_mm
        solid = np.array([w * t**3 / 12, t * w**3 / 12, rect_torsion(w, t)])
        hollow = np.array(
            [
                (w * t**3 - cw * ct**3) / 12,
                (t * w**3 - ct * cw**3) / 12,
                bredt_torsion(w, t, (w - cw) / 2, c.chamber_wall_mm),
            ]
        )
        window = np.clip(np.sum(self._chamber_window_z(np.asarray(z, float)), axis=0), 0, 1)
        section = solid[None] + window[:, None] * (hollow - solid)[None]
        pk = self.pressure_kpa(inflation_ml)
        local = np.tensordot(pk, self._chamber_window_z(np.asarray(z, float)), axes=1)
        return section * np.array([e, e, g])[None] * (1.0 + c.pressure_stiffening_per_kpa * local)[:, None]

    def _load_point(self, point: Touch, inflation_ml) -> tuple[float, tuple[float, float]]:
        """Arc position and section offset (x, y) of a surface point (rest, on the axis grid)."""
        c = self.config
        u, v = point.uv_mm
        s_mm = float(self.axial_position(np.array([v]), inflation_ml)[0])
        if point.surface in SIDE:
            return s_mm, (float(u), SIDE[point.surface] * c.thickness_mm / 2)
        if point.surface in ("right", "left"):
            return s_mm, ((1.0 if point.surface == "right" else -1.0) * c.width_mm / 2, float(u))
        raise EctskinError(f"unknown surface {point.surface!r}: expected front, back, right or left")

    def pose(
        self,
        force_n,
        touch: Touch | tuple[Touch, ...] | None,
        inflation_ml,
        handling: Handling | None = None,
    ):
        """The deformed axis for each frame.

        Returns ``(zs, r, R)``: the stretched rest grid (n_z,), the axis (F, n_z, 3) and the
        section frames (F, n_z, 3, 3). Each finger presses along its face's inward normal (front
        −y, back +y) with its ``force_n`` (see :func:`touch_loads` for the shapes) and pushes
        along the face with ``handling.shear_n``; the hand pushes at ``handling.push`` with
        ``handling.push_force_n``.
        """
        touches, forces = touch_loads(force_n, touch)
        n_f = forces.shape[0]
        force = np.atleast_1d(np.asarray(force_n, dtype=np.float64))
        key = pose_key(force, touch, inflation_ml, handling)
        if key in self._poses:
            return self._poses[key]
        zs = self.axial_position(self._zgrid, inflation_ml)
        n_h = handling.n_frames() if handling is not None else None
        if n_h is not None and n_h != n_f:
            raise EctskinError(f"handling gives {n_h} frames of loads but the finger force {n_f}")
        shear = None
        if touches and handling is not None and handling.shear_n is not None:
            shear = np.asarray(handling.shear_n, dtype=np.float64)
            shear = shear.reshape(n_f, 2) if shear.ndim < 3 else shear.reshape(n_f, len(touches), 2)
        loads = []
        for k, t in enumerate(touches):
            s_t, off = self._load_point(t, inflation_ml)
            vec = np.zeros((n_f, 3))
            if t.surface in SIDE:
                vec[:, 1] = -SIDE[t.surface] * forces[:, k]
            if shear is not None and (shear.ndim == 3 or k == 0):
                one = shear if shear.ndim == 2 else shear[:, k]
                vec[:, 0] += one[:, 0]
                vec[:, 2] += one[:, 1]
            loads.append(PointLoad(s_t, off, vec))
        if handling is not None and handling.push is not None:
            s_h, off = self._load_point(handling.push, inflation_ml)
            push = np.asarray(handling.push_force_n, dtype=np.float64).reshape(n_f, 3)
            loads.append(PointLoad(s_h, off, push))
        stiffness = self.section_stiffness(self._zgrid, inflation_ml)
        r, rot = solve_rod(zs, stiffness, loads, n_f, tol_mm=self.config.rod_tol_mm)
        # the last 8 always, up to POSES_KEPT while their frames fit (a response field's grid
        # row: each touch's pose is asked for by its cavity cells, electrodes and fingertip)
        while len(self._poses) >= POSES_KEPT or (
            len(self._poses) >= 8
            and sum(v[1].shape[0] for v in self._poses.values()) + n_f > POSE_FRAMES_KEPT
        ):
            self._poses.pop(next(iter(self._poses)))
        self._poses[key] = (zs, r, rot)
        return zs, r, rot

    def dimple_depth_mm(self, force_n, touch: Touch, inflation_ml) -> np.ndarray:
        """Indentation depth under the finger, F / k_d with k_d rising with local pressure."""
        c = self.config
        key = (self.check_inflation(inflation_ml).tobytes(), touch.uv_mm[1])
        k = self._dimple_k.get(key)  # (a placement dents the same point a dozen times)
        if k is None:
            pk = self.pressure_kpa(inflation_ml)
            local = float(np.tensordot(pk, self._chamber_window_z(np.array([touch.uv_mm[1]])), axes=1)[0])
            k = c.dimple_stiffness_n_per_mm * (1.0 + c.dimple_stiffening_per_kpa * local)
            remember(self._dimple_k, key, k, kept=64)
        return np.asarray(force_n, dtype=np.float64) / k

    # ------------------------------------------------------------------ surface map
    def deform(
        self,
        surface: str,
        uv_mm: np.ndarray,
        inflation_ml,
        touch: Touch | tuple[Touch, ...] | None = None,
        force_n=0.0,
        handling: Handling | None = None,
        *,
        keep_rest: bool = False,
    ) -> np.ndarray:
        """Map rest surface coordinates to deformed 3D points, one set per force value.

        Parameters
        ----------
        surface : "front" | "back" | "right" | "left"
        uv_mm : (n, 2) rest surface coordinates, the same points in every frame; or (F, n, 2),
            a set of points per frame (a fingertip's skin under its pad moves with its force).
        inflation_ml : (n_chambers,) chamber volumes.
        touch : the finger's contact, a tuple of fingers' contacts, or None.
        force_n : scalar or (F,) touch force per frame; (F, T) for a tuple of T touches.
        handling : the finger's shear and the hand's push per frame (F rows), or None.
        keep_rest : keep the state's part (bulge, pull-in, stretch) of these (n, 2) points, for
            points deformed touch after touch (a sensor's panels); the same numbers as without.

        Returns
        -------
        (F, n, 3) deformed positions in mm (F = 1 for a scalar force).
        """
        return self.surface_map(surface, inflation_ml, touch, force_n, handling)(uv_mm, keep_rest)

    def surface_map(
        self, surface: str, inflation_ml, touch: Touch | tuple[Touch, ...] | None = None,
        force_n=0.0, handling: Handling | None = None,
    ) -> SurfaceMap:
        """:meth:`deform` of ``surface`` under these loads as a function of the points (a
        :class:`~ectskin.twin.surface_map.SurfaceMap`), the same numbers: what does not depend
        on the points found once, for points mapped many times (a placement's skin samples)."""
        p = self.check_inflation(inflation_ml)
        touches, forces = touch_loads(force_n, touch)
        if surface not in SIDE and surface not in ("right", "left"):
            raise EctskinError(f"unknown surface {surface!r}: expected front, back, right or left")
        dents = [(t.uv_mm, self.dimple_depth_mm(forces[:, k], t, p))
                 for k, t in enumerate(touches) if t.surface == surface and surface in SIDE]
        zs, r, rot = self.pose(force_n, touch, p, handling)
        return SurfaceMap(self, surface, SIDE.get(surface), p, forces.shape[0], dents,
                          self._state_tables(surface, p), zs, axis_table(r, rot))

    def _state_tables(self, surface: str, p: np.ndarray) -> tuple[np.ndarray, Any]:
        """(bulge heights, :meth:`_arc_table`) of state ``p`` on a face (nothing on the sides)."""
        if surface not in SIDE:
            return np.empty(0), None
        heights = self.bulge_height_mm(p)
        return heights, self._arc_table(heights)

    def _rest_part(
        self, surface: str, uv: np.ndarray, p: np.ndarray, state: tuple[np.ndarray, Any]
    ) -> tuple[np.ndarray, ...]:
        """(x, z, offset, zq): the state's part of :meth:`deform` for rest points ``uv``: section
        offset, pulled-in z, bulge offset (x and offset empty on the sides), stretched z;
        ``state``: :meth:`_state_tables` of ``p``."""
        c = self.config
        if surface in SIDE:
            heights, table = state
            x = uv[..., 0]
            phi = self._window_x(x)
            z = uv[..., 1] - self._pull_in(x, uv[..., 1], table, phi)
            # the bulge (bulge_mm), (n,) or (F, n)
            offset = c.thickness_mm / 2 + phi * np.tensordot(heights, self._chamber_window_z(z), axes=1)
        elif surface in ("right", "left"):
            x = offset = np.empty(0)
            z = uv[..., 1]
        else:
            raise EctskinError(f"unknown surface {surface!r}: expected front, back, right or left")
        return x, z, np.asarray(offset), self.axial_position(z, p)

    def face_frame(
        self,
        surface: str,
        uv_mm,
        inflation_ml,
        touch: Touch | tuple[Touch, ...] | None = None,
        force_n=0.0,
        handling: Handling | None = None,
    ) -> np.ndarray:
        """(F, n, 3, 3) the face's axes at rest carried by the body's bending and twist: columns
        the u axis, the v axis and the outward normal (front +y, back −y, right +x, left −x) at
        each point, orthonormal. The section frame at the point's axial position; the bulges and
        dimples are left out: the normal is the direction a finger presses the face along,
        whatever the skin's local slope under it (:mod:`ectskin.twin.sensor`)."""
        p = self.check_inflation(inflation_ml)
        uv = np.asarray(uv_mm, dtype=np.float64).reshape(-1, 2)
        if surface in SIDE:  # u along x, v along the axis
            z = uv[:, 1] - self._face_pull_in(uv[:, 0], uv[:, 1], self.bulge_height_mm(p))
            rest = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, SIDE[surface], 0.0]]).T
        elif surface in ("right", "left"):  # u along y', v along the axis
            z = uv[:, 1]
            side = 1.0 if surface == "right" else -1.0
            rest = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [side, 0.0, 0.0]]).T
        else:
            raise EctskinError(
                f"unknown surface {surface!r}: expected front, back, right or left"
            )
        zs, _, rot = self.pose(force_n, touch, p, handling)
        zq = self.axial_position(z, p)
        j = np.clip(np.searchsorted(zs, zq) - 1, 0, zs.size - 2)
        w = ((zq - zs[j]) / (zs[j + 1] - zs[j]))[None, :, None, None]
        # (F, n, 3, 3) orthonormal again (interpolated rotations are not quite), columns kept
        q, r_ = np.linalg.qr((1 - w) * rot[:, j] + w * rot[:, j + 1])
        frames = q * np.sign(np.einsum("...ii->...i", r_))[..., None, :]
        return frames @ rest

    def surface_normal(
        self, surface: str, uv_mm, inflation_ml, touch=None, force_n=0.0, handling=None, h=0.05
    ):
        """(F, n, 3) outward unit normal of the deformed surface (finite differences)."""
        uv = np.asarray(uv_mm, dtype=np.float64).reshape(-1, 2)
        steps = np.array([[h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]])
        pts = self.deform(
            surface, (uv[None] + steps[:, None]).reshape(-1, 2), inflation_ml, touch, force_n, handling
        ).reshape(-1, 4, uv.shape[0], 3)
        pu = pts[:, 0] - pts[:, 1]
        pv = pts[:, 2] - pts[:, 3]
        n = np.cross(pu, pv)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        # orient outward: front +y, back -y, right +x, left -x (at rest)
        sign = {"front": 1.0, "back": -1.0, "right": 1.0, "left": -1.0}[surface]
        axis = 1 if surface in SIDE else 0
        flip = np.sign(n[..., axis]) != sign
        n[flip] *= -1
        return n
