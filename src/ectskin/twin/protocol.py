"""The paper's experiment (§3) as a parameterised protocol, and its trial plan.

Default: 27 inflation states (each chamber in {0, 10, 20} ml); per state one 30-s trial without
contact, then 6 trials of 30 s touching one region (3 front, 3 back) with a force that varies over
the trial; over all states every region is touched at least once. 189 trials × 900 frames.
Every level, count, duration, noise figure and the seed is a parameter, so unseen inflation levels
(say 5 and 15 ml) or other fingers can be simulated.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout
from ectskin.twin.readout import MocapConfig, ReadoutConfig

#: The strongest press a finger gives in these trials (N); beyond it the model is not meant to go.
MAX_FINGER_FORCE_N = 20.0
#: The strongest push of the handling hand (N).
MAX_HAND_PUSH_N = 10.0


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
    touch_dwells: int = 1  # finger placements per touch trial: it slides to a new point D-1 times
    lifts: bool = False  # lift the finger now and then (lift and re-press), per-frame labels
    finger_radius_mm: float = 8.0  # (assumed)
    force_nodes: int = 5  # MoM solves per touch trial (Chebyshev nodes in force)
    readout: ReadoutConfig = field(default_factory=ReadoutConfig)
    mocap: MocapConfig = field(default_factory=MocapConfig)

    def __post_init__(self) -> None:
        if not self.levels_ml:
            raise EctskinError("protocol: levels_ml must hold at least one inflation level")
        if self.touch_trials < 0:
            raise EctskinError(f"protocol: touch_trials must be >= 0, got {self.touch_trials}")
        if not (0 < self.duration_s < 1e5 and 0 < self.frame_rate_hz <= 1e4):
            raise EctskinError(
                f"protocol: duration_s and frame_rate_hz must be finite and > 0 (at most 1e5 s "
                f"and 1e4 Hz), got {self.duration_s}, "
                f"{self.frame_rate_hz}"
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
        if self.touch_dwells < 1:
            raise EctskinError(f"protocol: touch_dwells must be >= 1, got {self.touch_dwells}")
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
    def n_trials(self) -> int:
        return len(self.states()) * (self.touch_trials + int(self.no_contact_trial))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Protocol:
        d = dict(d)
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
        for k in ("levels_ml", "force_range_n", "tremor_hz"):
            if k in d:
                d[k] = tuple(d[k])
        return cls(**d)


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


def region_bounds(region, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners (u, v) of ``region`` shrunk by ``margin`` of its size on each side."""
    du, dv = region.u_mm[1] - region.u_mm[0], region.v_mm[1] - region.v_mm[0]
    lo = np.array([region.u_mm[0] + margin * du, region.v_mm[0] + margin * dv])
    hi = np.array([region.u_mm[1] - margin * du, region.v_mm[1] - margin * dv])
    return lo, hi


def plan_trials(protocol: Protocol, layout: SensorLayout) -> list[TrialPlan]:
    """The ordered trial plan of an experiment (deterministic for ``protocol.seed``)."""
    rng = np.random.default_rng([protocol.seed, 0xE5])
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

    plans: list[TrialPlan] = []
    counters = {f: 0 for f in faces}
    touch_idx = 0
    for s, p in enumerate(states):
        kinds = (["no_contact"] if protocol.no_contact_trial else []) + ["touch"] * protocol.touch_trials
        for k, kind in enumerate(kinds):
            region, surface, uv, occ = 0, None, None, False
            if kind == "touch":
                j = k - int(protocol.no_contact_trial)
                face = faces[j % 2] if by_face[faces[j % 2]] else faces[1 - j % 2]
                reg = seqs[face][counters[face] % len(seqs[face])]
                counters[face] += 1
                lo, hi = region_bounds(reg, protocol.touch_margin)
                if protocol.touch_placement == "uniform":
                    pts = rng.uniform(lo, hi, size=(protocol.touch_dwells, 2))
                else:
                    centre = np.asarray(reg.centre_mm)
                    pts = centre + rng.normal(0.0, protocol.touch_scatter_mm, (protocol.touch_dwells, 2))
                    pts = np.clip(pts, lo, hi)
                uv = tuple((float(a), float(b)) for a, b in pts)
                region, surface = reg.id, face
                occ = touch_idx in occluded
                touch_idx += 1
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
                )
            )
    return plans
