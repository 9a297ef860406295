"""The paper's experiment (§3) as a parameterised protocol, and its trial plan.

Default: 27 inflation states (each chamber in {0, 10, 20} ml); per state one 30-s trial without
contact, then 6 trials of 30 s touching one region (3 front, 3 back) with a force that varies over
the trial; over all states every region is touched at least once. 189 trials × 900 frames.
Every level, count, duration, noise figure and the seed is a parameter, so unseen inflation levels
(say 5 and 15 ml) or other fingers can be simulated.

**A second finger** (option ``second_finger``, the fraction of touch trials drawn from the seed
in which it also presses; default 0, none). Where to: a region other than the first finger's,
on the same face or the other one (either, 50/50, then the other if the first choice has no
room), placed like the first finger (``touch_placement``). On the same face its aimed point is at
least :func:`finger_separation_mm` from each of the first finger's aimed points: the widest
finger's width (2 × the largest radius drawn, so the two fingertips never overlap) plus
4 × ``slide_mm`` for the pads' roll and slide (assumed); on the other face the body lies between
them and any point goes. It presses at one point (no dwells) and, unlike the first finger, not
for the whole trial: it lands after a random delay and leaves before the end
(:func:`ectskin.twin.human.second_finger_path`), so a two-finger trial holds frames with one and
with two contacts. The second finger is drawn from its own random stream, so the option never
changes the first finger, the hand or the trials without a second finger: at 0 every result is
what it was without the option.

**People differ** (``finger_variability``, on by default): each touch trial's fingers draw
their fingertip radius and pulp modulus from ``finger_radius_range_mm`` and
``finger_modulus_range_mpa`` (:func:`ectskin.twin.human.trial_fingers`), from the trial's own
stream, so switching it off changes nothing else of the trial.

**Dense touches** (the contact experiment, ``ectskin.pipeline.config``): many dwells per trial
(``touch_dwells``), the finger sliding in contact from one point to the next over the last
``dwell_slide_s`` of each (:func:`ectskin.twin.human.dwell_points`), read from the states'
response fields (``response="field"``: :mod:`ectskin.twin.field_response`; the default
``"solve"`` keeps the method-of-moments solves per dwell of :mod:`ectskin.twin.response`, the
paper's protocol's documented reading).

**Random streams.** Every draw comes from :meth:`Protocol.rng`, seeded by (seed, …); an
experiment with ``stream`` > 0 draws from streams of its own (seed, :data:`STREAM_TAG`, stream,
…), so two experiments with one seed (the paper's and the contact experiment) share no draw.

**Size.** The twin holds a whole recording in memory, so one simulated experiment is bounded
(:func:`check_recording_size`, called by :func:`plan_trials` and by ``ectskin simulate`` before
any work): at most :data:`MAX_TRIALS` trials and :data:`MAX_RECORDING_BYTES` of recording,
estimated as frames × (pairs + 3 × markers + 5 per-frame values) × 8 bytes
(:func:`recording_nbytes`; the paper's protocol: 189 trials, 170 100 frames, about 65 MB).
A larger data set is several recordings (other seeds).
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option, check_seed
from ectskin.layout import SensorLayout
from ectskin.twin.readout import MocapConfig, ReadoutConfig

#: The strongest press a finger gives in these trials (N); beyond it the model is not meant to go.
MAX_FINGER_FORCE_N = 20.0
#: The strongest push of the handling hand (N).
MAX_HAND_PUSH_N = 10.0
#: The most trials one simulated experiment plans (the paper's protocol: 189).
MAX_TRIALS = 100_000
#: The largest recording one simulated experiment makes, as estimated by
#: :func:`recording_nbytes` (about 60 times the paper's protocol; it is held in memory).
MAX_RECORDING_BYTES = 4 * 2**30
#: Per-frame values of a recording besides the readout and the markers (time, force, contact
#: point (u, v), finger height), each 8 bytes, in :func:`recording_nbytes`.
FRAME_VALUES = 5
#: How a touch trial's readout is computed (``Protocol.response``).
RESPONSES = ("solve", "field")
#: The second seed word of the random streams of an experiment with ``Protocol.stream`` > 0 (no
#: stream of stream 0 starts (seed, STREAM_TAG, ...): its second words are 1, 2 and 0xE5).
STREAM_TAG = 0x5EED


@dataclass(frozen=True)
class Protocol:
    """Parameters of a simulated experiment (defaults: the paper's protocol)."""

    levels_ml: tuple[float, ...] = (0.0, 10.0, 20.0)
    n_chambers: int = 3
    touch_trials: int = 6  # per state, alternating front / back
    no_contact_trial: bool = True  # one trial per state without contact, first
    duration_s: float = 30.0
    frame_rate_hz: float = 30.0
    seed: int = 0
    force_range_n: tuple[float, float] = (0.3, 2.0)  # (assumed) finger force range
    force_knot_s: float = 2.5  # (assumed) the force changes smoothly on this time scale
    # the human finger (see ectskin.twin.human; all assumed): tremor band and size, roll/slide
    tremor_hz: tuple[float, float] = (8.0, 12.0)
    tremor_rel: float = 0.02
    slide_mm: float = 0.5
    slide_tau_s: float = 3.0
    shear_ratio: float = 0.3  # tangential / normal force, drawn per trial in [0, this]
    # options: approach from above and retreat at the ends, hover periods, lift and re-press
    approach: bool = False
    approach_s: float = 1.0
    approach_height_mm: float = 100.0  # (assumed) from where the finger is barely sensed
    hover: bool = False
    hover_max_mm: float = 15.0
    # the experimenter's hand (manual handling): push up to this force, wandering on this scale
    push_max_n: float = 2.0  # (assumed) a light push, about 200 g-force; 0 switches the hand off
    push_knot_s: float = 3.0
    # where the finger lands in its region: "aimed" = the region's centre plus the experimenter's
    # Gaussian scatter (touch_scatter_mm, clipped to the region shrunk by touch_margin);
    # "uniform" = anywhere in the region shrunk by touch_margin per side
    touch_placement: str = "aimed"  # (assumed: the paper's sub-regions are marked on the robot)
    touch_scatter_mm: float = 3.0  # (assumed) human aiming scatter, per axis
    touch_margin: float = 0.15  # keep touches this fraction of the region size inside each edge
    # finger placements per touch trial: it moves to a new point of the region D-1 times (the
    # paper's "randomly touch a sub-region": docs/paper-reading.md says why 8, sliding, is the
    # default reading)
    touch_dwells: int = 8
    lifts: bool = False  # lift the finger now and then (lift and re-press), per-frame labels
    finger_radius_mm: float = 8.0  # (assumed) every fingertip's radius without finger_variability
    # people differ (ectskin.twin.human.trial_fingers): each trial's fingers (the second its own)
    # draw their fingertip radius and pulp modulus uniformly from these ranges (assumed: adult
    # fingertips; pulp under light touch); off: finger_radius_mm and the default pulp (0.1 MPa)
    finger_variability: bool = True
    finger_radius_range_mm: tuple[float, float] = (7.0, 10.0)
    finger_modulus_range_mpa: tuple[float, float] = (0.05, 0.2)
    force_nodes: int = 5  # MoM solves per touch trial (Chebyshev nodes in force)
    # how a touch trial's readout is computed: "solve" = method-of-moments solves per dwell
    # (ectskin.twin.response), "field" = read from the state's response field
    # (ectskin.twin.field_response; simulate_experiment needs the fields)
    response: str = "solve"
    # seconds at the end of each dwell in which the finger slides, in contact, to the next dwell's
    # point (a raised-cosine path); 0 = it jumps there between two frames; None = the whole dwell
    # (duration_s / touch_dwells: one continuous contact that moves over the region). Read it
    # through Protocol.slide_s
    dwell_slide_s: float | None = None
    # which random streams the experiment draws from (Protocol.rng): 0 = (seed, ...), as always;
    # another number gives another experiment with the same seed streams of its own
    stream: int = 0
    # fraction of touch trials (drawn from the seed) in which a second finger also presses a
    # different region for part of the trial (see the module docstring); 0 = never
    second_finger: float = 0.0
    readout: ReadoutConfig = field(default_factory=ReadoutConfig)
    mocap: MocapConfig = field(default_factory=MocapConfig)

    def __post_init__(self) -> None:
        if not self.levels_ml:
            raise EctskinError("protocol: levels_ml must hold at least one inflation level")
        levels = np.asarray(self.levels_ml, dtype=np.float64)
        if not np.all(np.isfinite(levels)):
            raise EctskinError(
                f"protocol: levels_ml must be finite volumes (ml), got {self.levels_ml}"
            )
        if np.unique(levels).size != levels.size:
            raise EctskinError(
                f"protocol: levels_ml must be distinct inflation levels, got {self.levels_ml} "
                "(a level given twice repeats every state it is in)"
            )
        _check_whole("n_chambers", self.n_chambers, 1)
        check_seed("seed", self.seed, source="protocol")
        _check_whole("touch_trials", self.touch_trials, 0)
        if not (0 < self.duration_s < 1e5 and 0 < self.frame_rate_hz <= 1e4):
            raise EctskinError(
                f"protocol: duration_s and frame_rate_hz must be finite and > 0 (at most 1e5 s "
                f"and 1e4 Hz), got {self.duration_s}, "
                f"{self.frame_rate_hz}"
            )
        if self.n_frames < 1:
            raise EctskinError(
                f"protocol: a trial of duration_s {self.duration_s} at frame_rate_hz "
                f"{self.frame_rate_hz} holds {self.duration_s * self.frame_rate_hz:.3g} frames; "
                "it needs at least one"
            )
        lo, hi = self.force_range_n
        if not (0 < lo < hi <= MAX_FINGER_FORCE_N):
            raise EctskinError(
                f"protocol: force_range_n must be 0 < low < high <= {MAX_FINGER_FORCE_N} N (a "
                f"finger's press), got {self.force_range_n}"
            )
        check_option("touch_placement", self.touch_placement, ("aimed", "uniform"), source="protocol")
        if self.touch_scatter_mm < 0:
            raise EctskinError(f"protocol: touch_scatter_mm must be >= 0, got {self.touch_scatter_mm}")
        if not 0 <= self.touch_margin < 0.5:
            raise EctskinError(f"protocol: touch_margin must be in [0, 0.5), got {self.touch_margin}")
        # (a protocol without touch trials never uses it, however short its trials)
        _check_whole("touch_dwells", self.touch_dwells, 1,
                     self.n_frames if self.touch_trials else None, "the frames of a trial")
        lo_hz, hi_hz = self.tremor_hz
        if not 0 < lo_hz <= hi_hz < self.frame_rate_hz / 2:
            raise EctskinError(
                f"protocol: tremor_hz must be 0 < low <= high < frame_rate_hz / 2 (Nyquist), got "
                f"{self.tremor_hz}"
            )
        for name in ("tremor_rel", "slide_mm", "shear_ratio", "push_max_n"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise EctskinError(f"protocol: {name} must be a finite number >= 0, got {v!r}")
        if self.push_max_n > MAX_HAND_PUSH_N:
            raise EctskinError(
                f"protocol: push_max_n must be at most {MAX_HAND_PUSH_N} N (a hand handling the "
                f"soft body; more buckles it beyond what the rod model carries), got {self.push_max_n}"
            )
        if self.tremor_rel >= 0.5:
            raise EctskinError(f"protocol: tremor_rel must be < 0.5, got {self.tremor_rel}")
        for name in ("slide_tau_s", "approach_s", "approach_height_mm", "hover_max_mm", "push_knot_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise EctskinError(f"protocol: {name} must be a finite number > 0, got {v!r}")
        if self.hover_max_mm < 1.0:
            raise EctskinError(f"protocol: hover_max_mm must be >= 1, got {self.hover_max_mm}")
        if not (isinstance(self.finger_radius_mm, int | float) and 2.0 <= self.finger_radius_mm <= 30.0):
            raise EctskinError(
                f"protocol: finger_radius_mm must be a fingertip's radius, 2 to 30 mm, got "
                f"{self.finger_radius_mm!r}"
            )
        if not isinstance(self.finger_variability, bool):
            raise EctskinError(
                f"protocol: finger_variability must be True or False, got "
                f"{self.finger_variability!r}"
            )
        _check_range("finger_radius_range_mm", self.finger_radius_range_mm, 2.0, 30.0,
                     "fingertip radii (mm)")
        _check_range("finger_modulus_range_mpa", self.finger_modulus_range_mpa, 0.0, 10.0,
                     "pulp moduli (MPa)", low_open=True)
        x = self.second_finger
        if isinstance(x, bool) or not isinstance(x, int | float) or not 0.0 <= x <= 1.0:
            raise EctskinError(
                f"protocol: second_finger must be a fraction of the touch trials, a number from "
                f"0 to 1, got {x!r}"
            )
        check_option("response", self.response, RESPONSES, source="protocol")
        v = self.dwell_slide_s
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float) or not (
            np.isfinite(v) and 0 <= v <= self.duration_s / self.touch_dwells
        )):
            raise EctskinError(
                f"protocol: dwell_slide_s must be a number of seconds from 0 to duration_s / "
                f"touch_dwells ({self.duration_s / self.touch_dwells:.4g}, one dwell), or None "
                f"(the whole dwell), got {v!r}"
            )
        _check_whole("stream", self.stream, 0)
        if self.force_nodes < 2:
            raise EctskinError(f"protocol: force_nodes must be >= 2, got {self.force_nodes}")
        if self.touch_trials == 0 and not self.no_contact_trial:
            raise EctskinError("protocol: no trials (touch_trials=0 and no_contact_trial=False)")

    @property
    def n_frames(self) -> int:
        return int(round(self.duration_s * self.frame_rate_hz))

    def states(self) -> list[tuple[float, ...]]:
        """Inflation states p = (p1, …, p_n): every combination of the levels."""
        return [tuple(s) for s in itertools.product(self.levels_ml, repeat=self.n_chambers)]

    @property
    def n_states(self) -> int:
        """Inflation states: every combination of the levels (counted, not listed)."""
        return len(self.levels_ml) ** self.n_chambers

    @property
    def n_trials(self) -> int:
        return self.n_states * (self.touch_trials + int(self.no_contact_trial))

    def rng(self, *keys: int) -> np.random.Generator:
        """The experiment's random stream ``keys``: seeded by (seed, *keys) for ``stream`` 0,
        by (seed, :data:`STREAM_TAG`, stream, *keys) otherwise (so an experiment of another
        stream shares no draw with the paper's, whatever its seed)."""
        if self.stream == 0:
            return np.random.default_rng([self.seed, *keys])
        return np.random.default_rng([self.seed, STREAM_TAG, self.stream, *keys])

    @property
    def slide_s(self) -> float:
        """Seconds at the end of each dwell in which the finger slides to the next dwell's point:
        ``dwell_slide_s``, or the whole dwell (``duration_s / touch_dwells``) when it is None;
        0 with one dwell (there is no next point)."""
        if self.touch_dwells <= 1:
            return 0.0
        if self.dwell_slide_s is None:
            return self.duration_s / self.touch_dwells
        return float(self.dwell_slide_s)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Protocol:
        d = dict(d)
        # written before the sliding reading became the default: one point held per trial
        d.setdefault("touch_dwells", 1)
        d.setdefault("dwell_slide_s", 0.0)
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise EctskinError(f"protocol: unknown fields {sorted(unknown)}")
        if "readout" in d:
            d["readout"] = ReadoutConfig(**d["readout"])
        if "mocap" in d:
            m = dict(d["mocap"])
            for k in ("occlusion_events", "occlusion_frames"):
                if k in m:
                    m[k] = tuple(m[k])
            d["mocap"] = MocapConfig(**m)
        for k in ("levels_ml", "force_range_n", "tremor_hz", "finger_radius_range_mm",
                  "finger_modulus_range_mpa"):
            if k in d:
                d[k] = tuple(d[k])
        return cls(**d)


def _check_whole(
    name: str, value: Any, low: int, high: int | None = None, high_is: str = ""
) -> None:
    """Refuse a protocol count that is not a whole number from ``low`` (to ``high``)."""
    ok = not isinstance(value, bool) and isinstance(value, int | np.integer)
    if ok and (value < low or (high is not None and value > high)):
        ok = False
    if not ok:
        upto = f" to {high_is} ({high})" if high is not None else " or more"
        raise EctskinError(
            f"protocol: {name} must be a whole number from {low}{upto}, got {value!r}"
        )


def _check_range(
    name: str, value: Any, low: float, high: float, what: str, low_open: bool = False
) -> None:
    """Refuse a protocol range that is not two numbers ``low`` <= a <= b <= ``high`` (a > low
    with ``low_open``)."""
    ok = isinstance(value, tuple | list) and len(value) == 2
    if ok:
        a, b = value
        ok = all(isinstance(x, int | float) and not isinstance(x, bool) for x in (a, b))
        ok = ok and bool(np.isfinite([a, b]).all()) and (a > low if low_open else a >= low)
        ok = ok and a <= b <= high
    if not ok:
        bound = f"{low} < low" if low_open else f"{low} <= low"
        raise EctskinError(
            f"protocol: {name} must be two {what}, {bound} <= high <= {high}, got {value!r}"
        )


def recording_nbytes(protocol: Protocol, layout: SensorLayout) -> int:
    """The estimated size (bytes) of the recording of ``protocol`` on ``layout``: frames × (pairs
    + 3 × markers + :data:`FRAME_VALUES`) × 8 bytes (float64 readouts, marker coordinates and
    per-frame ground truth)."""
    per_frame = layout.n_pairs + 3 * layout.n_markers + FRAME_VALUES
    return protocol.n_trials * protocol.n_frames * per_frame * 8


def check_recording_size(protocol: Protocol, layout: SensorLayout) -> None:
    """Refuse an experiment over :data:`MAX_TRIALS` trials or :data:`MAX_RECORDING_BYTES` of
    recording (:func:`recording_nbytes`), naming the size it would have. Cheap: nothing is
    planned or allocated."""
    n_trials, n_frames = protocol.n_trials, protocol.n_frames
    nbytes = recording_nbytes(protocol, layout)
    if n_trials <= MAX_TRIALS and nbytes <= MAX_RECORDING_BYTES:
        return
    frames = n_trials * n_frames
    raise EctskinError(
        f"protocol: {n_trials} trials ({protocol.n_states} inflation state(s) x "
        f"{protocol.touch_trials + int(protocol.no_contact_trial)}) x {n_frames} frames = "
        f"{frames} frames x ({layout.n_pairs} pairs + 3 x {layout.n_markers} marker coordinates + "
        f"{FRAME_VALUES} per-frame values) x 8 bytes = {_size(nbytes)}, held in memory; one "
        f"simulated recording holds at most {MAX_TRIALS} trials and {_size(MAX_RECORDING_BYTES)} "
        "(ectskin.twin.protocol.MAX_TRIALS, MAX_RECORDING_BYTES): simulate fewer or shorter "
        "trials (touch_trials, levels_ml, duration_s, frame_rate_hz), or several recordings"
    )


def _size(nbytes: int) -> str:
    """``4.0 GiB``, ``70 MiB``: a size for a message."""
    if nbytes >= 2**30:
        return f"{nbytes / 2**30:.1f} GiB"
    return f"{nbytes / 2**20:.0f} MiB"


@dataclass(frozen=True)
class TrialPlan:
    """What one trial does; drawn from the protocol's seed, independent of worker count."""

    index: int
    name: str
    state: int
    inflation: tuple[float, ...]
    kind: str  # "no_contact" | "touch"
    region: int  # 0 for no contact
    surface: str | None
    touch_uv_mm: tuple[tuple[float, float], ...] | None  # one point per dwell
    start_s: float  # start on the experiment clock
    marker_delay_frames: int
    occluded: bool
    # the second finger (Protocol.second_finger), None/0 without one: its face, region and aimed
    # point (u, v) in mm
    second_surface: str | None = None
    second_region: int = 0
    second_uv_mm: tuple[float, float] | None = None


def region_bounds(region, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners (u, v) of ``region`` shrunk by ``margin`` of its size on each side."""
    du, dv = region.u_mm[1] - region.u_mm[0], region.v_mm[1] - region.v_mm[0]
    lo = np.array([region.u_mm[0] + margin * du, region.v_mm[0] + margin * dv])
    hi = np.array([region.u_mm[1] - margin * du, region.v_mm[1] - margin * dv])
    return lo, hi


def finger_separation_mm(protocol: Protocol) -> float:
    """Least distance (mm) between the two fingers' aimed points on one face: the width of the
    widest finger the protocol draws (``finger_radius_range_mm``'s high end with
    ``finger_variability``, else ``finger_radius_mm``) plus room for both pads' roll and slide
    (4 × ``slide_mm``, assumed)."""
    radius = (
        protocol.finger_radius_range_mm[1]
        if protocol.finger_variability
        else protocol.finger_radius_mm
    )
    return 2.0 * radius + 4.0 * protocol.slide_mm


def _placements(reg, protocol: Protocol, rng, n: int) -> np.ndarray:
    """(n, 2) points where the experimenter lands in region ``reg`` (``touch_placement``)."""
    lo, hi = region_bounds(reg, protocol.touch_margin)
    if protocol.touch_placement == "uniform":
        return rng.uniform(lo, hi, size=(n, 2))
    pts = np.asarray(reg.centre_mm) + rng.normal(0.0, protocol.touch_scatter_mm, (n, 2))
    return np.clip(pts, lo, hi)


def second_placement(
    protocol: Protocol,
    layout: SensorLayout,
    first_surface: str,
    first_region: int,
    first_uv: np.ndarray,
    rng,
    tries: int = 50,
) -> tuple[str, int, tuple[float, float]]:
    """Face, region and aimed point (u, v) of a second finger (the rule of the module docstring).

    ``first_uv`` (D, 2): the first finger's aimed points. Raises an :class:`EctskinError` if no
    region of ``layout`` leaves room for it.
    """
    other = "back" if first_surface == "front" else "front"
    faces = (first_surface, other) if rng.random() < 0.5 else (other, first_surface)
    gap = finger_separation_mm(protocol)
    for face in faces:
        regions = [r for r in layout.regions if r.surface == face and r.id != first_region]
        if not regions:
            continue
        for _ in range(tries):
            reg = regions[int(rng.integers(len(regions)))]
            uv = _placements(reg, protocol, rng, 1)[0]
            if face != first_surface or np.min(np.linalg.norm(first_uv - uv, axis=1)) >= gap:
                return face, reg.id, (float(uv[0]), float(uv[1]))
    raise EctskinError(
        f"layout {layout.name!r}: no region leaves room for a second finger {gap:.1f} mm from the "
        f"first (region {first_region} on the {first_surface} face); set second_finger=0"
    )


def plan_trials(protocol: Protocol, layout: SensorLayout) -> list[TrialPlan]:
    """The ordered trial plan of an experiment (deterministic for ``protocol.seed``); an
    experiment over the size bounds is refused first (:func:`check_recording_size`)."""
    check_recording_size(protocol, layout)
    rng = protocol.rng(0xE5)
    states = protocol.states()
    faces = ("front", "back")
    by_face = {f: [r for r in layout.regions if r.surface == f] for f in faces}
    if protocol.touch_trials and not any(by_face.values()):
        raise EctskinError(f"layout {layout.name!r} has no touch regions on the front or back face")
    # region sequences per face: concatenated random permutations, so every region comes up once
    # before any comes up twice
    n_per_face = {
        f: len(states) * len(range(i, protocol.touch_trials, 2)) for i, f in enumerate(faces)
    }
    seqs: dict[str, list] = {}
    for f in faces:
        seq: list = []
        while by_face[f] and len(seq) < n_per_face[f]:
            seq += [by_face[f][k] for k in rng.permutation(len(by_face[f]))]
        seqs[f] = seq
    n_touch = len(states) * protocol.touch_trials
    n_occl = int(round(n_touch * protocol.mocap.occluded_fraction))
    occluded = set(rng.choice(n_touch, size=n_occl, replace=False).tolist()) if n_touch else set()

    # the second finger draws from its own stream: the option leaves every other draw unchanged
    rng2 = protocol.rng(0xE5, 2) if protocol.second_finger > 0 else None
    plans: list[TrialPlan] = []
    counters = {f: 0 for f in faces}
    touch_idx = 0
    for s, p in enumerate(states):
        kinds = (["no_contact"] if protocol.no_contact_trial else []) + ["touch"] * protocol.touch_trials
        for k, kind in enumerate(kinds):
            region, surface, uv, occ = 0, None, None, False
            second: dict = {}
            if kind == "touch":
                j = k - int(protocol.no_contact_trial)
                face = faces[j % 2] if by_face[faces[j % 2]] else faces[1 - j % 2]
                reg = seqs[face][counters[face] % len(seqs[face])]
                counters[face] += 1
                pts = _placements(reg, protocol, rng, protocol.touch_dwells)
                uv = tuple((float(a), float(b)) for a, b in pts)
                region, surface = reg.id, face
                occ = touch_idx in occluded
                touch_idx += 1
                if rng2 is not None and rng2.random() < protocol.second_finger:
                    face2, reg2, uv2 = second_placement(
                        protocol, layout, face, reg.id, np.asarray(uv), rng2
                    )
                    second = {"second_surface": face2, "second_region": reg2, "second_uv_mm": uv2}
            index = len(plans)
            plans.append(
                TrialPlan(
                    index=index,
                    name=f"trial_{index:04d}",
                    state=s,
                    inflation=tuple(float(v) for v in p),
                    kind=kind,
                    region=region,
                    surface=surface,
                    touch_uv_mm=uv,
                    start_s=index * protocol.duration_s,
                    marker_delay_frames=int(rng.integers(0, protocol.mocap.max_delay_frames + 1)),
                    occluded=occ,
                    **second,
                )
            )
    return plans
