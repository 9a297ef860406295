"""The experimenter in the twin: a human finger and a handling hand, frame by frame.

Everything here is a per-frame trajectory drawn from a trial's random stream; the mechanics and
electrostatics turn it into deformation and readouts (:mod:`ectskin.twin.simulate`).

**The finger** (paper §3: "we randomly touch a sub-region of the robot and induce different
deformations by changing the contact force"). By default it stays on the skin for the whole trial,
as in the paper. Its

* force wanders smoothly (monotone cubic through random knots every ``force_knot_s``) and
  trembles: physiological tremor, a narrow-band oscillation of ``tremor_hz`` whose amplitude is
  ``tremor_rel`` of the force (assumed: 8-12 Hz, 1-3 % of the force in steady pinch/press);
* contact point rolls and slides within its region: an Ornstein-Uhlenbeck walk of standard
  deviation ``slide_mm`` and time constant ``slide_tau_s`` around the aimed point, kept inside
  the region (assumed: 0.5 mm, 3 s: the pressed pad rolls and creeps, it does not wander);
* pushes a little off-axis: a tangential force ``shear_ratio`` × the normal force in a direction
  drawn per trial (assumed: up to 0.3, inside skin-on-silicone friction of μ ≈ 0.5-1);
* contact patch grows with the force (Hertz; :class:`~ectskin.twin.finger.Finger`).

**A second finger** (``Protocol.second_finger``, :func:`second_finger_path`) presses at one
point of another region with the same force model (smooth walk, tremor), roll and slide and
off-axis push as the first, drawn independently. It lands after a delay drawn uniformly in
10-40 % of the trial and leaves at 60-90 % of it (assumed), so a trial with it holds one- and
two-contact frames. It arrives and leaves between frames (no approach or hover of its own); in
the frames without it, it is away from the body: no contact, force 0, point and height NaN.

Options (the contact models need them): ``approach`` (the trial begins with the finger coming
down from ``approach_height_mm`` and ends with it retreating), ``hover`` (periods above the skin
at 1 to ``hover_max_mm`` instead of contact) and ``lifts`` (lift off to a few centimetres and
press again). Frames not in contact carry force 0 and their finger height. ``touch_dwells``
points per trial: the finger moves to the next one for each equal share of the trial; with
``dwell_slide_s`` it slides there in contact over the end of each share
(:func:`dwell_points`), and above the skin it hovers over its way instead of over the trial's
mean contact point.

**The fingers differ** (:func:`trial_fingers`, ``Protocol.finger_variability``, on by default):
each trial is touched by a person's finger whose fingertip radius and pulp modulus are drawn
uniformly from ``finger_radius_range_mm`` and ``finger_modulus_range_mpa`` (assumed: adult
fingertips of 7-10 mm radius; pulp of 0.05-0.2 MPa under light touch); a second finger draws its
own. Off, every finger is the protocol's (``finger_radius_mm``, the default pulp).

**The hand** (manual handling, "external (manual handling) forces"): per trial it pushes at a
random point of the body's distal half, on a face or a side, in a fixed direction across the
body's axis (off-centre and off-axis: it bends the body both ways and twists it), with a force
that wanders smoothly between 0 and ``push_max_n``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import PchipInterpolator

from ectskin.twin.finger import Finger
from ectskin.twin.mechanics import Handling, Touch


@dataclass(frozen=True)
class FingerPath:
    """Per-frame finger state of one trial (n frames)."""

    contact: np.ndarray  # (n,) bool: on the skin
    uv_mm: np.ndarray  # (n, 2) the point on the face under the fingertip (x, z), mm
    force_n: np.ndarray  # (n,) normal force, N (0 when not in contact)
    height_mm: np.ndarray  # (n,) fingertip above the skin, mm (0 in contact)
    shear_n: np.ndarray  # (n, 2) tangential force along the face's (x, z), N


def smooth_walk(n: int, fps: float, knot_s: float, lo: float, hi: float, rng) -> np.ndarray:
    """(n,) monotone cubic (PCHIP) through uniform random values in [lo, hi] every ``knot_s``."""
    duration = n / fps
    n_knots = max(2, int(np.ceil(duration / knot_s)) + 1)
    tk = np.linspace(0.0, duration, n_knots)
    return np.clip(PchipInterpolator(tk, rng.uniform(lo, hi, n_knots))(np.arange(n) / fps), lo, hi)


def tremor(n: int, fps: float, band_hz: tuple[float, float], rng) -> np.ndarray:
    """(n,) unit-RMS narrow-band oscillation: a sum of 8 sines with random frequencies in the
    band and random phases (physiological tremor)."""
    t = np.arange(n) / fps
    f = rng.uniform(*band_hz, 8)
    ph = rng.uniform(0, 2 * np.pi, 8)
    return np.sin(2 * np.pi * f[None, :] * t[:, None] + ph[None, :]).sum(axis=1) / 2.0


def ou_walk(n: int, fps: float, sigma: float, tau_s: float, rng) -> np.ndarray:
    """(n, 2) Ornstein-Uhlenbeck walk, stationary standard deviation ``sigma`` per axis."""
    a = np.exp(-1.0 / (fps * tau_s))
    out = np.empty((n, 2))
    out[0] = rng.normal(0, sigma, 2)
    kicks = rng.normal(0, sigma * np.sqrt(1 - a * a), (n, 2))
    for i in range(1, n):
        out[i] = a * out[i - 1] + kicks[i]
    return out


def contact_schedule(n: int, fps: float, rng, on_s=(4.0, 10.0), off_s=(1.5, 4.0)) -> np.ndarray:
    """(n,) bool: in contact for on_s, off for off_s, alternating; starts off for 0.5-2 s."""
    mask = np.zeros(n, dtype=bool)
    i = int(rng.uniform(0.5, 2.0) * fps)
    on = True
    while i < n:
        dur = rng.uniform(*on_s) if on else rng.uniform(*off_s)
        j = min(n, i + int(dur * fps))
        mask[i:j] = on
        on = not on
        i = j
    return mask


def _ease(x: np.ndarray) -> np.ndarray:
    """Smooth 0 → 1 (a raised cosine) for x in [0, 1]."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))


def dwell_points(n: int, fps: float, aimed_uv: np.ndarray, slide_s: float) -> np.ndarray:
    """(n, 2) the aimed point of each frame: the D dwells' points (D, 2), each for an equal share
    of the frames; with ``slide_s`` > 0 the last ``slide_s`` of each dwell (at most all but its
    first frame) moves from its point to the next one along a raised cosine, arriving at the
    next dwell's first frame (the finger slides there in contact). No random draw."""
    uv = np.empty((n, 2))
    splits = np.array_split(np.arange(n), len(aimed_uv))
    for aim, frames in zip(aimed_uv, splits):
        uv[frames] = aim
    if slide_s <= 0:
        return uv
    for k in range(len(aimed_uv) - 1):
        frames = splits[k]
        m = min(int(round(slide_s * fps)), frames.size - 1)
        if m <= 0:
            continue
        moving = frames[-m:]
        t = _ease((np.arange(m) + 1.0) / (m + 1.0))[:, None]
        uv[moving] = aimed_uv[k] + t * (aimed_uv[k + 1] - aimed_uv[k])
    return uv


def finger_path(
    n: int, fps: float, aimed_uv: np.ndarray, lo_uv, hi_uv, protocol, rng
) -> FingerPath:
    """The finger over one touch trial; ``aimed_uv`` (D, 2) are the aimed points of its dwells
    (the finger moves to the next one for each equal share of the trial, sliding there for the
    last ``protocol.slide_s`` of each: :func:`dwell_points`), kept in [lo, hi]."""
    f_lo, f_hi = protocol.force_range_n
    force = smooth_walk(n, fps, protocol.force_knot_s, f_lo, f_hi, rng)
    force = force * (1.0 + protocol.tremor_rel * tremor(n, fps, protocol.tremor_hz, rng))
    force = np.maximum(force, 0.05 * f_lo)
    uv = dwell_points(n, fps, np.asarray(aimed_uv, dtype=np.float64), protocol.slide_s)
    if protocol.slide_mm > 0:
        uv = uv + ou_walk(n, fps, protocol.slide_mm, protocol.slide_tau_s, rng)
    uv = np.clip(uv, lo_uv, hi_uv)
    height = np.zeros(n)
    contact = np.ones(n, dtype=bool)
    if protocol.lifts:
        contact &= contact_schedule(n, fps, rng)
        lift = rng.uniform(10.0, 40.0)
        height = np.where(contact, 0.0, lift)
    if protocol.hover:
        hovering = ~contact_schedule(n, fps, rng, on_s=(3.0, 8.0), off_s=(2.0, 5.0))
        contact &= ~hovering
        height = np.where(
            hovering, smooth_walk(n, fps, 1.0, 1.0, protocol.hover_max_mm, rng), height
        )
    if protocol.approach:
        k = min(n // 4, int(round(protocol.approach_s * fps)))
        if k > 0:
            ramp = protocol.approach_height_mm * (1.0 - _ease(np.arange(k) / k))
            contact[:k] = False
            height[:k] = np.maximum(height[:k], ramp)
            contact[-k:] = False
            height[-k:] = np.maximum(height[-k:], ramp[::-1])
    # above the skin the finger hovers over the trial's mean contact point (it lands within a
    # millimetre of it: the roll and slide of the pressed pad); a finger that slides between
    # dwells (dwell_slide_s) hovers over its way instead
    if not contact.all() and protocol.slide_s == 0:
        uv[~contact] = uv[contact].mean(axis=0) if contact.any() else np.mean(aimed_uv, axis=0)
    force = np.where(contact, force, 0.0)
    height = np.where(contact, 0.0, np.maximum(height, 0.5))
    angle = rng.uniform(0, 2 * np.pi)
    ratio = rng.uniform(0.0, protocol.shear_ratio)
    shear = force[:, None] * ratio * np.array([np.cos(angle), np.sin(angle)])[None, :]
    return FingerPath(contact, uv, force, height, shear)


def second_finger_path(n: int, fps: float, aimed_uv, lo_uv, hi_uv, protocol, rng) -> FingerPath:
    """The second finger over one trial: aimed at ``aimed_uv`` (2,), kept in [lo, hi], on the skin
    from a random landing frame to a random leaving frame (module docstring), away otherwise."""
    f_lo, f_hi = protocol.force_range_n
    force = smooth_walk(n, fps, protocol.force_knot_s, f_lo, f_hi, rng)
    force = force * (1.0 + protocol.tremor_rel * tremor(n, fps, protocol.tremor_hz, rng))
    force = np.maximum(force, 0.05 * f_lo)
    uv = np.broadcast_to(np.asarray(aimed_uv, dtype=np.float64), (n, 2)).copy()
    if protocol.slide_mm > 0:
        uv = uv + ou_walk(n, fps, protocol.slide_mm, protocol.slide_tau_s, rng)
    uv = np.clip(uv, lo_uv, hi_uv)
    land = max(1, int(rng.uniform(0.1, 0.4) * n))
    leave = min(n - 1, max(land + 1, int(rng.uniform(0.6, 0.9) * n)))
    contact = np.zeros(n, dtype=bool)
    contact[land:leave] = True
    angle = rng.uniform(0, 2 * np.pi)
    ratio = rng.uniform(0.0, protocol.shear_ratio)
    force = np.where(contact, force, 0.0)
    uv[~contact] = np.nan
    height = np.where(contact, 0.0, np.nan)
    shear = force[:, None] * ratio * np.array([np.cos(angle), np.sin(angle)])[None, :]
    return FingerPath(contact, uv, force, height, shear)


def hand_push(n: int, fps: float, protocol, rng, manipulator_config) -> Handling:
    """The experimenter's hand over one trial (``protocol.push_max_n`` = 0: no hand).

    The hand's random numbers are drawn either way, so that a trial simulated without the hand
    is the same trial (finger, readout noise, markers' noise) as with it, less the hand: the
    metrics with manual handling on and off compare like with like."""
    c = manipulator_config
    surface = ("front", "back", "right", "left")[int(rng.integers(4))]
    z = rng.uniform(c.length_mm / 2, c.length_mm - 5.0)
    across = c.width_mm / 2 - 5.0 if surface in ("front", "back") else c.thickness_mm / 2 - 2.0
    point = Touch(surface, (float(rng.uniform(-across, across)), float(z)))
    direction = rng.normal(size=2)
    direction /= np.linalg.norm(direction)
    # a hand pushes into the body where it rests on it: on a face the normal part points inwards
    inward = {"front": (1, -1.0), "back": (1, 1.0), "right": (0, -1.0), "left": (0, 1.0)}[surface]
    direction[inward[0]] = inward[1] * abs(direction[inward[0]])
    magnitude = smooth_walk(n, fps, protocol.push_knot_s, 0.0, protocol.push_max_n, rng)
    if protocol.push_max_n <= 0:
        return Handling()
    force = np.zeros((n, 3))
    force[:, :2] = magnitude[:, None] * direction[None, :]
    return Handling(push=point, push_force_n=force)


def trial_fingers(protocol, base: Finger, rng) -> tuple[Finger, Finger]:
    """The trial's first and second finger: ``base`` with a radius and a pulp modulus drawn
    uniformly from the protocol's ranges, each finger its own (``finger_variability``); off,
    ``base`` with the protocol's ``finger_radius_mm`` for both (nothing is drawn)."""
    if not protocol.finger_variability:
        same = replace(base, radius_mm=float(protocol.finger_radius_mm))
        return same, same
    radius = rng.uniform(*protocol.finger_radius_range_mm, 2)
    modulus = rng.uniform(*protocol.finger_modulus_range_mpa, 2)
    first, second = (
        replace(base, radius_mm=float(r), pulp_modulus_mpa=float(m))
        for r, m in zip(radius, modulus)
    )
    return first, second
