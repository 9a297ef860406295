"""The finger and how it rests on the skin: the fingertip's shape, its pulp and the cover under
it (:class:`Finger`), and where it sits in each frame (:func:`rest_fingertips`, a
:class:`Fingertip`), which :class:`~ectskin.twin.sensor.SensorModel` turns into panels.

**The contact: every fingertip rests on the skin** (:func:`rest_fingertips`), in every frame,
state and force, and above the skin (hover) too:

* *Axis.* A finger presses its face along the face's normal as the body carries it (the rod's
  section frame at the finger's point, :meth:`~ectskin.twin.mechanics.Manipulator.face_frame`):
  the chambers' bulges and the dimple under the pad do not turn the finger (the skin's local
  normal tilts by up to 60° on a bulge's side wall, and a finger placed along it leaned off the
  face).
* *Shape.* The fingertip is a sphere of radius R whose pad is pressed flat by the Hertz
  indentation δ (:meth:`Finger.indentation_mm`): its lower surface lies R − δ below the centre
  out to the pad's rim ρ = √(δ (2R − δ)), then follows the sphere. Its panels are the lower half
  of a cubed sphere with the corners beyond the pad's plane moved onto it (:func:`flatten_cap`),
  so they follow the indentation continuously.
* *Rest height.* The skin under the fingertip is sampled on rings about its axis (on the pad up
  to its rim, and on the rounded rest out to 1.25 R), at lateral distances that move with the
  pad, taken back to rest surface coordinates by Newton steps through the deformation (the
  skin stretches, and rises steeply beside a bulge). For a sample at lateral distance r that
  rises w along the axis above the finger's point p, the centre must be at least
  g = w + (the lower surface's depth below the centre at r) above p, plus the cover under the
  pad. The centre rests at τ ln Σ exp(g_i / τ) (τ = :data:`CONTACT_SMOOTHING_MM`) plus the cover
  (and the hover height): the rest height of an exponential contact law, never below the
  highest sample's need and smooth in force and point (a lift that switches on at a threshold
  made steps of tens of fF in the readout). Only the samples that weigh in it are solved: a
  sample whose need cannot come within :data:`_PRUNE_MARGIN_MM` of the highest (judged at each
  Newton step from its lateral miss and a bound on the skin's slope) is dropped, its weight
  below e⁻⁵⁰; the others are solved as if all were, so the rest height is the same to
  round-off at about a third of the cost. Frames that differ only in the height above the skin
  (a hovering finger) share one placement. Fingers that hover (force 0) leave the body as it is,
  so many of them (a response field's grid row) are placed at once on the one untouched skin
  (:func:`hover_fingertips`, :func:`hovering`), with the same steps as each alone.
* *Cover.* The sealing cover (``Finger.skin_cover_mm``) under the pressed pad is a bonded thin
  soft layer, a Winkler foundation: it compresses by the mean pressure F / (π a²) over the
  Hertz contact disc divided by the bonded layer's compression modulus E_c = E (1 + 2 S²), S =
  a / (2h) (:meth:`Finger.cover_mm`; E of Ecoflex 00-30, assumed).

The samples are finite, so between them the skin may rise a hair into the cover; the tests
bound that on a dense independent grid over points, inflation states and forces
(``tests/twin/test_contact_geometry.py``).

**Fingers differ.** A :class:`Finger` has its radius and pulp modulus;
:meth:`~ectskin.twin.sensor.SensorModel.with_fingers` gives a sensor with other fingers (one per
touch) cheaply, sharing the rest-state panels: the simulation draws each trial's
(:func:`ectskin.twin.human.trial_fingers`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np

from ectskin._check import EctskinError
from ectskin.twin.mechanics import Handling, Manipulator, Touch

#: the length scale (mm) of the smooth contact law that rests a fingertip on the skin under its
#: pad (module docstring): its rest height exceeds the hard contact's by at most
#: CONTACT_SMOOTHING_MM · ln(number of skin samples + 1) (< 0.08 mm), and is smooth in force and
#: point
CONTACT_SMOOTHING_MM = 0.01
#: where the skin under a fingertip is sampled: rings about its axis on the pressed pad, at these
#: fractions of the flat pad's radius ρ ...
_PAD_RINGS = tuple(np.arange(1, 7) / 6)
#: ... and rings beyond it, at ρ + t (_REACH · R − ρ) for these t ...
_TIP_RINGS = tuple(np.arange(1, 17) / 16)
#: ... out to this many fingertip radii (the samples beyond R keep a sample's need continuous as
#: it leaves from under the fingertip) ...
_REACH = 1.25
#: ... where the sampled skin is held below a cone of this slope
_CONE_SLOPE = 10.0
#: ... each with this many points
_RING_POINTS = 64
#: Newton steps that find the rest coordinates of the skin samples, the first of them with a new
#: Jacobian each, the rest with the last one (converged to < 1e-4 mm over the faces, inflation
#: states and forces of the tests)
_PLACE_STEPS = 6
_JACOBIAN_STEPS = 2
#: samples whose need may not come within this of the highest are not solved (they weigh less
#: than exp(−this / CONTACT_SMOOTHING_MM) = e⁻⁵⁰ in the contact law) ...
_PRUNE_MARGIN_MM = 0.5
#: ... bounding the skin's slope under a fingertip (up to ~60° beside a bulge) by this ...
_SLOPE_BOUND = 5.0
#: ... and solving every sample that may come within this of the face's edge (mm)
_EDGE_MARGIN_MM = 2.0
#: the smooth bound of the pad's indentation at R / 2 (:meth:`Finger.indentation_mm`)
_CAP_POWER = 12


@dataclass(frozen=True)
class Finger:
    """The grounded finger: a fingertip (hemisphere) on a shaft (cylinder), both radius R, and
    the skin's sealing cover it rests on (module docstring: the contact)."""

    radius_mm: float = 8.0  # (assumed) adult fingertip; people differ: 7-10 mm (Protocol)
    shaft_length_mm: float = 50.0
    skin_cover_mm: float = 1.0  # (assumed) sealing layer between the wires and the finger
    # (assumed) effective contact modulus E* of the fingertip pulp: soft tissue of ~0.05-0.2 MPa
    # under light touch; with R = 8 mm a 2 N press flattens a disc of ~5 mm radius
    pulp_modulus_mpa: float = 0.1
    # (assumed) Young's modulus of the cover: Ecoflex 00-30, whose 100 % modulus is about 10 psi
    # (Smooth-On's datasheet), E ≈ 0.07 MPa; math.inf: a cover that does not compress
    cover_modulus_mpa: float = 0.07
    # (assumed) the cover compresses at most to (1 - this) of its thickness (a smooth bound)
    cover_max_strain: float = 0.5

    def __post_init__(self) -> None:
        for name in ("radius_mm", "shaft_length_mm", "pulp_modulus_mpa"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise EctskinError(f"finger: {name} must be a positive number, got {v!r}")
        if not (np.isfinite(self.skin_cover_mm) and self.skin_cover_mm >= 0):
            raise EctskinError(f"finger: skin_cover_mm must be >= 0, got {self.skin_cover_mm!r}")
        v = self.cover_modulus_mpa
        if not (isinstance(v, int | float) and v > 0 and not np.isnan(v)):
            raise EctskinError(
                f"finger: cover_modulus_mpa must be a positive number (MPa; inf = a cover that "
                f"does not compress), got {v!r}"
            )
        if not (isinstance(self.cover_max_strain, int | float) and 0 < self.cover_max_strain < 1):
            raise EctskinError(
                f"finger: cover_max_strain must be a fraction in (0, 1), got "
                f"{self.cover_max_strain!r}"
            )

    def indentation_mm(self, force_n):
        """Hertz indentation δ = (9F² / (16 R E*²))^(1/3) of the pulp (mm), bounded by R/2.

        The bound is a smooth minimum, (δ⁻¹² + (R/2)⁻¹²)^(−1/12): it changes δ by < 0.3 % below
        three quarters of the bound and has no kink where a soft, small fingertip reaches it
        within the force range (a hard ``min`` made a step in ∂C/∂F there). ``force_n``: a
        number or an array (float or array back)."""
        f = np.maximum(np.asarray(force_n, dtype=np.float64), 0.0)
        d = (9 * f**2 / (16 * self.radius_mm * self.pulp_modulus_mpa**2)) ** (1 / 3)
        cap = self.radius_mm / 2
        with np.errstate(divide="ignore"):
            out = np.where(d > 0, (d ** -_CAP_POWER + cap**-_CAP_POWER) ** (-1 / _CAP_POWER), 0.0)
        return out if out.ndim else float(out)

    def contact_radius_mm(self, force_n):
        """Hertz contact radius a = √(R δ) (mm)."""
        out = np.sqrt(self.radius_mm * np.asarray(self.indentation_mm(force_n)))
        return out if out.ndim else float(out)

    def cover_mm(self, force_n):
        """The cover's thickness under the pressed pad (mm): a bonded thin layer (Winkler).

        The mean pressure P = F / (π a²) over the Hertz contact disc compresses a layer of
        thickness h bonded to the wires and pressed by the pad by the strain ε = P / E_c, with the
        compression modulus of a bonded layer E_c = E (1 + 2 S²) and the shape factor
        S = loaded area / free side area = π a² / (2π a h) = a / (2h) (Gent and Lindley's thin
        bonded block). ε is bounded smoothly by ``cover_max_strain`` (ε_max tanh(ε / ε_max)).
        Above the skin (force 0) the cover keeps its thickness."""
        f = np.maximum(np.asarray(force_n, dtype=np.float64), 0.0)
        h = self.skin_cover_mm
        a2 = self.radius_mm * np.asarray(self.indentation_mm(f))  # a²
        if h <= 0 or np.isinf(self.cover_modulus_mpa):
            out = np.full(f.shape, h)
        else:
            e_c = self.cover_modulus_mpa * (1.0 + 2.0 * a2 / (4.0 * h * h))  # 1 + 2 S²
            with np.errstate(divide="ignore", invalid="ignore"):
                strain = np.where(a2 > 0, f / (np.pi * a2 * e_c), 0.0)
            m = self.cover_max_strain
            out = h * (1.0 - m * np.tanh(strain / m))
        return out if out.ndim else float(out)


@dataclass(frozen=True)
class Fingertip:
    """Where one fingertip rests in each of F frames (:func:`rest_fingertips`,
    :meth:`~ectskin.twin.sensor.SensorModel.fingertips`).

    Its solid is the sphere of ``finger.radius_mm`` about ``centre_mm`` cut flat by the plane
    ``pad_depth_mm`` inside the sphere's lowest point, normal to ``axis`` (the pressed pad),
    on a shaft along ``axis``; ``cover_mm`` is the cover's thickness under the pad, the least gap
    the fingertip keeps to the skin under it along ``axis`` (plus ``height_mm`` above the skin).
    """

    finger: Finger
    point_mm: np.ndarray  # (F, 3) the finger's point on the deformed skin
    axis: np.ndarray  # (F, 3) unit: the face's outward normal as the body carries it there
    centre_mm: np.ndarray  # (F, 3) the fingertip sphere's centre
    pad_depth_mm: np.ndarray  # (F,) δ: the pad pressed flat this far (0 above the skin)
    cover_mm: np.ndarray  # (F,) the cover's thickness under the pad
    height_mm: np.ndarray  # (F,) above the skin (0 in contact)


def rest_fingertips(
    manipulator: Manipulator,
    fingers,
    inflation_ml,
    touch: Touch | tuple[Touch, ...],
    forces: np.ndarray,
    per_touch: np.ndarray,
    heights: np.ndarray,
    handling: Handling | None = None,
) -> list[Fingertip]:
    """One :class:`Fingertip` per touch of ``touch``: ``fingers`` (one :class:`Finger` per touch),
    ``forces`` as given to the mechanics, ``per_touch`` and ``heights`` (F, T) each finger's force
    and height above the skin per frame; every fingertip on the skin deformed by all of them."""
    touches = (touch,) if isinstance(touch, Touch) else tuple(touch)
    placed = _PLACED.get()
    if placed is not None and isinstance(touch, Touch) and handling is None:
        key = _hover_key(manipulator, fingers[0], inflation_ml, heights[:, 0])
        if key == placed[0] and not np.any(forces) and touch in placed[1]:
            return [placed[1][touch]]
    return [
        _rest_one(
            manipulator, fingers[k], t, inflation_ml, touch, forces, per_touch[:, k],
            heights[:, k], handling,
        )
        for k, t in enumerate(touches)
    ]


def hover_fingertips(
    manipulator: Manipulator, finger: Finger, inflation_ml, touches: Sequence[Touch], heights
) -> list[Fingertip]:
    """The fingertips of ``finger`` hovering at ``heights`` (H,) above each of ``touches``
    (single touches, force 0): element t is ``rest_fingertips(manipulator, [finger],
    inflation_ml, touches[t], zeros(H), zeros((H, 1)), heights[:, None])[0]``, to round-off.

    A finger that does not press leaves the body as it is (no dimple, no load on the rod), so
    all of them rest on the untouched skin and are placed together, one frame per touch (and,
    as in :func:`rest_fingertips`, one placement for all the heights): the same Newton steps
    for every skin sample, a dozen mappings of the skin for all the touches instead of a dozen
    for each (the later steps map a few dozen samples per touch, where the cost of a mapping
    is mostly its own)."""
    touches = tuple(touches)
    if not touches or not all(isinstance(t, Touch) for t in touches):
        raise EctskinError(f"hover_fingertips: touches must be Touch, got {touches!r:.80}")
    heights = np.atleast_1d(np.asarray(heights, dtype=np.float64))
    if heights.ndim != 1 or not np.all(heights > 0):
        raise EctskinError(
            f"hover_fingertips: heights must be (H,) heights above the skin > 0 mm, got "
            f"{heights.tolist()}"
        )
    n_h = heights.size
    out: dict[int, Fingertip] = {}
    for surface in dict.fromkeys(t.surface for t in touches):
        idx = [k for k, t in enumerate(touches) if t.surface == surface]
        uv = np.asarray([touches[k].uv_mm for k in idx], dtype=np.float64)  # (T, 2)
        n_t = len(idx)
        zeros = np.zeros(n_t)

        # (T, k, 2) -> (T, k, 3) on the untouched body, one frame per touch
        deform = manipulator.surface_map(surface, inflation_ml, None, zeros)
        pts = deform(uv[:, None])[:, 0]  # (T, 3)
        frame = manipulator.face_frame(surface, uv, inflation_ml)[0]  # (T, 3, 3)
        depth, cover, target = _pad(finger, np.zeros(1), np.zeros(1, dtype=bool))
        depths = np.repeat(depth, n_t)
        skin, valid = _skin_at(
            manipulator, surface, deform, uv[:, None], np.repeat(target, n_t, axis=0), pts,
            frame, finger.radius_mm, depths,
        )
        above = rest_height(skin - pts[:, None], frame[..., 2], finger.radius_mm, depths,
                            valid=valid)
        for g, k in enumerate(idx):  # every height: the same placement, lifted
            p = np.repeat(pts[g : g + 1], n_h, axis=0)
            n = np.repeat(frame[g : g + 1, :, 2], n_h, axis=0)
            c = np.repeat(cover, n_h)
            centre = p + n * (above[g] + c + heights)[:, None]
            out[k] = Fingertip(finger, p, n, centre, np.zeros(n_h), c, heights.copy())
    return [out[k] for k in range(len(touches))]


#: the placements of :func:`hovering` while its block runs: (key, {touch: Fingertip})
_PLACED: ContextVar[tuple[tuple, dict[Touch, Fingertip]] | None] = ContextVar(
    "ectskin_hovering", default=None
)


def _hover_key(manipulator: Manipulator, finger: Finger, inflation_ml, heights) -> tuple:
    """What a hovering placement depends on besides its touch."""
    def raw(a) -> bytes:
        return np.ascontiguousarray(a, dtype=np.float64).reshape(-1).tobytes()

    return (id(manipulator), finger, raw(inflation_ml), raw(heights))


@contextmanager
def hovering(
    manipulator: Manipulator, finger: Finger, inflation_ml, touches: Sequence[Touch], heights
) -> Iterator[list[Fingertip]]:
    """Place ``touches`` hovering at ``heights`` at once (:func:`hover_fingertips`) and, inside
    the block, answer :func:`rest_fingertips` of any one of them (the same manipulator, finger,
    inflation and heights, force 0, no handling) with that placement: a response field's hover
    row solved by the twin's own calls (:meth:`~ectskin.twin.sensor.SensorModel.finger_panels`),
    placed as a row. Yields the fingertips."""
    tips = hover_fingertips(manipulator, finger, inflation_ml, touches, heights)
    key = _hover_key(manipulator, finger, inflation_ml, np.asarray(heights, dtype=np.float64))
    token = _PLACED.set((key, dict(zip(touches, tips))))
    try:
        yield tips
    finally:
        _PLACED.reset(token)


def _rest_one(
    m: Manipulator, fg: Finger, one: Touch, inflation_ml, touch, forces, force_one, heights_one,
    handling,
) -> Fingertip:
    """The :class:`Fingertip` of ``one`` (force (F,), height (F,) per frame) on the skin deformed
    by all of ``touch`` (forces ``forces``).

    Frames that differ only in the height above the skin (the same forces, no handling: a
    hovering finger at several heights) share the skin under the fingertip and its rest height:
    it is found once and lifted per frame."""
    contact = heights_one <= 0
    f_all = np.asarray(forces, dtype=np.float64)
    alike = (
        handling is None
        and len(force_one) > 1
        and bool(np.all(f_all == f_all[:1]))
        and bool(np.all(contact == contact[0]))
    )
    rows = slice(0, 1) if alike else slice(None)
    pts, nrm, depth, cover, above = _placement(
        m, fg, one, inflation_ml, touch, f_all[rows], force_one[rows], contact[rows], handling
    )
    if alike:
        n_f = len(force_one)
        pts, nrm, depth, cover, above = (
            np.repeat(a, n_f, axis=0) for a in (pts, nrm, depth, cover, above)
        )
    lift = np.maximum(heights_one, 0.0)
    centre = pts + nrm * (above + cover + lift)[:, None]
    return Fingertip(fg, pts, nrm, centre, depth, cover, lift)


def _placement(m: Manipulator, fg: Finger, one: Touch, inflation_ml, touch, forces, force_one,
               contact, handling):
    """(point (F, 3), axis (F, 3), pad depth (F,), cover (F,), rest height less the cover (F,))
    of ``one``'s fingertip in contact (``contact`` (F,) True) or above the skin."""
    uv = np.asarray([one.uv_mm])
    # rest points (F, k, 2) or (k, 2) -> the skin (F, k, 3) under these loads
    deform = m.surface_map(one.surface, inflation_ml, touch, forces, handling)
    pts = deform(uv)[:, 0]  # (F, 3)
    frame = m.face_frame(one.surface, uv, inflation_ml, touch, forces, handling)[:, 0]
    depth, cover, target = _pad(fg, force_one, contact)
    nrm = frame[..., 2]
    skin, valid = _skin_at(
        m, one.surface, deform, np.asarray(one.uv_mm), target, pts, frame, fg.radius_mm, depth
    )
    above = rest_height(skin - pts[:, None], nrm, fg.radius_mm, depth, valid=valid)
    return pts, nrm, depth, cover, above


def _pad(fg: Finger, force_one, contact) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pad depth (F,), cover (F,), the skin samples' lateral offsets along the face's axes
    (F, m, 2)) of ``fg`` pressing with ``force_one`` (F,) where ``contact`` (F,), else above."""
    depth = np.where(contact, fg.indentation_mm(force_one), 0.0)  # (F,)
    cover = np.where(contact, fg.cover_mm(force_one), fg.skin_cover_mm)
    rho = np.sqrt(depth * (2 * fg.radius_mm - depth))  # the flat pad's radius
    # the skin under the fingertip: rings about its axis at lateral distances that move with the
    # pad (each sample's need is then smooth in force; one ring on the pad's rim, where the
    # fingertip's lower surface has its edge)
    radii = np.concatenate(
        [rho[:, None] * np.asarray(_PAD_RINGS)[None],
         rho[:, None] + (_REACH * fg.radius_mm - rho)[:, None] * np.asarray(_TIP_RINGS)[None]],
        axis=1,
    )  # (F, rings)
    ang = np.linspace(0, 2 * np.pi, _RING_POINTS, endpoint=False)
    target = (radii[:, :, None, None] * np.c_[np.cos(ang), np.sin(ang)][None, None]).reshape(
        len(depth), -1, 2
    )  # (F, m, 2)
    return depth, cover, target


def _skin_at(
    m: Manipulator, surface: str, deform, uv0, target, pts, frame,
    radius: float | None = None, depth: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The deformed skin at the lateral offsets ``target`` (F, m, 2) from the points ``pts``
    (F, 3) along the face's carried axes ``frame`` (F, 3, 3) (u, v, normal): rest coordinates
    found by Newton steps through the deformation (the skin stretches and rises steeply beside
    a bulge; the flat face's map is the first guess), kept on the face. ``deform`` maps rest
    coordinates (F, k, 2) on ``surface`` to the deformed skin (F, k, 3), frame by frame;
    ``uv0``: the finger's rest point (2,), or one per frame (F, 1, 2).

    Returns the skin (F, k, 3) at k of the samples and a mask (F, k) of the valid ones. With
    ``radius`` and ``depth`` (F,) (the fingertip's), a sample is dropped at any step where its
    need cannot come within :data:`_PRUNE_MARGIN_MM` of the highest (:func:`_worth_solving`): it
    would weigh less than exp(−margin / τ) in the smooth contact law. Each sample's steps are its
    own, so the samples kept are solved exactly as when every sample is (k = m, all valid,
    without ``radius``)."""
    n_f, n_m = target.shape[:2]
    e12 = frame[..., :2].transpose(0, 2, 1)  # (F, 2, 3)
    h = 0.05  # the Jacobian's forward differences, mm
    steps = np.array([[h, 0.0], [0.0, h]])
    valid = np.ones((n_f, n_m), dtype=bool)
    offset = target
    inv = np.broadcast_to(np.eye(2), (n_f, n_m, 2, 2))
    # the lower surface's depth at each sample's (wanted) lateral distance, for the pruning
    lower = None
    if radius is not None and depth is not None:
        lower = _lower_depth(_length(target), radius, depth)
    for step in range(_PLACE_STEPS):
        fresh = step < _JACOBIAN_STEPS  # a new Jacobian, or the last one (chord steps)
        x = deform(uv0 + offset)
        lat = _along(x - pts[:, None], e12[:, None])  # (F, m, 2)
        if radius is not None and depth is not None and lower is not None:
            keep = valid & _worth_solving(
                m, surface, uv0 + offset, x - pts[:, None], lat, target, frame[..., 2],
                radius, depth, valid, lower,
            )
            if keep.sum(axis=1).max() < target.shape[1]:
                # each frame's kept samples first (in order), padded with its first (invalid)
                count = keep.sum(axis=1)
                k = max(1, int(count.max()))
                order = np.argsort(~keep, axis=1, kind="stable")[:, :k]
                valid = np.arange(k)[None] < count[:, None]
                idx = np.where(valid, order, order[:, :1])[..., None]
                target, offset, lat = (
                    np.take_along_axis(a, idx, axis=1) for a in (target, offset, lat)
                )
                lower = np.take_along_axis(lower, idx[..., 0], axis=1)
                if not fresh:
                    inv = np.take_along_axis(inv, idx[..., None], axis=1)
        if fresh:
            trial = (uv0 + offset)[:, None] + steps[None, :, None]  # (F, 2, m, 2)
            n_k = target.shape[1]
            xs = deform(trial.reshape(n_f, -1, 2)).reshape(n_f, 2, n_k, 3)
            lat_s = _along(xs - pts[:, None, None], e12[:, None, None])  # (F, 2, m, 2)
            jac = np.stack([lat_s[:, 0] - lat, lat_s[:, 1] - lat], axis=-1) / h
            # beyond the body's ends the map stops (such points are kept on the face at the
            # end): there a step takes the flat face's map
            det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
            flat = np.abs(det) < 0.1
            jac = np.where(flat[..., None, None], np.eye(2), jac)
            det = np.where(flat, 1.0, det)[..., None, None]
            inv = np.stack(
                [np.stack([jac[..., 1, 1], -jac[..., 0, 1]], axis=-1),
                 np.stack([-jac[..., 1, 0], jac[..., 0, 0]], axis=-1)], axis=-2
            ) / det  # (F, m, 2, 2), the 2 × 2 inverse
        miss = target - lat
        offset = offset + (inv[..., 0] * miss[..., 0:1] + inv[..., 1] * miss[..., 1:2])
    uv = _on_face(m, surface, uv0 + offset)
    return deform(uv), valid


def _worth_solving(
    m: Manipulator, surface: str, uv_guess, rel0, lat0, target, axis, radius: float, depth,
    valid, lower: np.ndarray | None = None,
) -> np.ndarray:
    """(F, m) the samples whose need (:func:`rest_height`) may come within
    :data:`_PRUNE_MARGIN_MM` of the largest, judged from the current guess (``rel0`` (F, m, 3)
    the deformed guess relative to the point, ``lat0`` its lateral offset, ``target`` the
    wanted; ``valid`` (F, m) the samples that count; ``lower``: the lower surface's depth at
    |``target``| (:func:`_lower_depth`), if the caller has it).

    Solved, a sample lies at lateral distance |target| (its lower-surface depth is known now)
    and its rise along the axis differs from the guess's by at most :data:`_SLOPE_BOUND` times
    the lateral miss |target − lat0| (the skin's slope under the fingertip is below that).
    Samples that may leave the face (whose solve is clipped to its edge, nearer the axis) are
    always solved."""
    up = _along(rel0, axis[:, None, None])[..., 0]
    d = _lower_depth(_length(target), radius, depth) if lower is None else lower
    miss = _SLOPE_BOUND * _length(target - lat0)
    low = np.where(valid, up + d - miss, -np.inf)
    best = np.maximum((radius - depth), low.max(axis=1))  # (F,)
    keep = up + d + miss >= best[:, None] - _PRUNE_MARGIN_MM
    c = m.config
    half = (c.width_mm if surface in ("front", "back") else c.thickness_mm) / 2
    reach = _EDGE_MARGIN_MM + miss / _SLOPE_BOUND * 2.0
    near_edge = (
        (np.abs(uv_guess[..., 0]) > half - reach)
        | (uv_guess[..., 1] < reach)
        | (uv_guess[..., 1] > c.length_mm - reach)
    )
    return keep | near_edge


def _along(d: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(..., k) the projections Σᵢ dᵢ aₖᵢ of the vectors ``d`` (..., 3) onto ``axes``
    (..., k, 3), broadcast (``np.einsum``'s, without its general loops)."""
    return (
        d[..., 0:1] * axes[..., 0] + d[..., 1:2] * axes[..., 1] + d[..., 2:3] * axes[..., 2]
    )


def _length(d: np.ndarray) -> np.ndarray:
    """(...) the lengths of the vectors ``d`` (..., 2) (as ``np.linalg.norm(d, axis=-1)``)."""
    return np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])


def _on_face(m: Manipulator, surface: str, uv: np.ndarray) -> np.ndarray:
    """``uv`` (..., 2) kept on the face ``surface``."""
    c = m.config
    half = (c.width_mm if surface in ("front", "back") else c.thickness_mm) / 2
    out = uv.copy()
    out[..., 0] = np.minimum(np.maximum(out[..., 0], -half), half)  # (np.clip's, quicker)
    out[..., 1] = np.minimum(np.maximum(out[..., 1], 0.0), c.length_mm)
    return out


def flatten_cap(centres, u, v, plane: float):
    """Press the part of a fingertip below z = −``plane`` (its own frame, pole at −z) flat onto
    that plane: each panel's corners below it are moved up onto it, and the panel is rebuilt
    from its corners (:meth:`~ectskin.electrostatics.Panels.from_quads`'s rule). A panel wholly
    below lies flat on the plane; one the plane cuts bends with it, so the panels follow the
    indentation continuously (moving whole panels by their centres made steps of ~0.5 fF in the
    readout as the force grew)."""
    corners = centres[:, None] + 0.5 * np.stack([-u - v, u - v, u + v, v - u], axis=1)  # (n, 4, 3)
    if not (corners[..., 2] < -plane).any():
        return centres, u, v
    corners[..., 2] = np.maximum(corners[..., 2], -plane)
    c0, c1, c2, c3 = corners.transpose(1, 0, 2)
    cut = (corners[..., 2] == -plane).any(axis=1)  # panels the plane reaches: rebuilt
    new_c = np.where(cut[:, None], corners.mean(axis=1), centres)
    new_u = np.where(cut[:, None], 0.5 * ((c1 - c0) + (c2 - c3)), u)
    new_v = np.where(cut[:, None], 0.5 * ((c3 - c0) + (c2 - c1)), v)
    return new_c, new_u, new_v


def rest_height(
    rel: np.ndarray, axis: np.ndarray, radius: float, depth: np.ndarray,
    valid: np.ndarray | None = None,
):
    """(F,) how far above the finger's point a fingertip's centre rests, less the cover: the
    smooth contact law (module docstring).

    ``rel`` (F, m, 3): skin samples under the fingertip relative to its point; ``axis`` (F, 3)
    the fingertip's unit axis; ``depth`` (F,) how far its pad is pressed flat; ``valid`` (F, m)
    the samples to count (default all). A sample at lateral distance r that rises u along the
    axis needs the centre u + d(r) above the point, d(r) the lower surface's depth below the
    centre (:func:`_lower_depth`). The point itself needs R − δ."""
    up = np.einsum("fmi,fi->fm", rel, axis)  # (F, m): how far each sample rises toward the finger
    r = np.linalg.norm(rel - up[..., None] * axis[:, None], axis=2)
    lower = _lower_depth(r, radius, depth)
    pad = np.broadcast_to((radius - depth)[:, None], lower.shape)
    need = lower + up
    if valid is not None:
        need = np.where(valid, need, -np.inf)
    return _soft_max(np.concatenate([pad[:, :1], need], axis=1), axis=1)  # (F, 1 + m)


def _lower_depth(r: np.ndarray, radius: float, depth: np.ndarray) -> np.ndarray:
    """(F, m) the depth of a fingertip's lower surface below its centre at lateral distances
    ``r`` (F, m): the flat pad's R − δ, then the sphere's √(R² − r²) (their smooth minimum, never
    above either), and beyond R a steep cone (the skin there is no concern; the cone keeps a
    sample's need continuous as it leaves from under the fingertip)."""
    sphere = np.sqrt(np.maximum(radius**2 - r**2, 0.0)) - _CONE_SLOPE * np.maximum(r - radius, 0)
    pad = np.broadcast_to((radius - depth)[:, None], sphere.shape)
    return -_soft_max(np.stack([-pad, -sphere]), axis=0)


def _soft_max(values: np.ndarray, axis: int) -> np.ndarray:
    """τ ln Σ exp(x / τ) along ``axis`` (τ = :data:`CONTACT_SMOOTHING_MM`): at least the
    maximum, at most τ ln(count) above it, and smooth."""
    tau = CONTACT_SMOOTHING_MM
    top = values.max(axis=axis, keepdims=True)
    out = top + tau * np.log(np.exp((values - top) / tau).sum(axis=axis, keepdims=True))
    return np.squeeze(out, axis=axis)
