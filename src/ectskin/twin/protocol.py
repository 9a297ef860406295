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
    # where the finger lands in its region: "aimed" = the region's centre plus the experimenter's
    # Gaussian scatter (touch_scatter_mm, clipped to the region shrunk by touch_margin);
    # "uniform" = anywhere in the region shrunk by touch_margin per side
    touch_placement: str = "aimed"  # (assumed: the paper's sub-regions are marked on the robot)
    touch_scatter_mm: float = 3.0  # (assumed) human aiming scatter, per axis
    touch_margin: float = 0.15  # keep touches this fraction of the region size inside each edge
    touch_dwells: int = 1  # finger placements per touch trial: it slides to a new point D-1 times
    lifts: bool = False  # lift the finger now and then, with per-frame contact labels
    finger_radius_mm: float = 8.0  # (assumed)
    force_nodes: int = 5  # MoM solves per touch trial (Chebyshev nodes in force)
    readout: ReadoutConfig = field(default_factory=ReadoutConfig)
    mocap: MocapConfig = field(default_factory=MocapConfig)

    def __post_init__(self) -> None:
        if not self.levels_ml:
            raise EctskinError("protocol: levels_ml must hold at least one inflation level")
        if self.touch_trials < 0:
            raise EctskinError(f"protocol: touch_trials must be >= 0, got {self.touch_trials}")
        if not (self.duration_s > 0 and self.frame_rate_hz > 0):
            raise EctskinError(
                f"protocol: duration_s and frame_rate_hz must be > 0, got {self.duration_s}, "
                f"{self.frame_rate_hz}"
            )
        lo, hi = self.force_range_n
        if not 0 < lo < hi:
            raise EctskinError(f"protocol: force_range_n must be 0 < low < high, got {self.force_range_n}")
        check_option("touch_placement", self.touch_placement, ("aimed", "uniform"), source="protocol")
        if self.touch_scatter_mm < 0:
            raise EctskinError(f"protocol: touch_scatter_mm must be >= 0, got {self.touch_scatter_mm}")
        if not 0 <= self.touch_margin < 0.5:
            raise EctskinError(f"protocol: touch_margin must be in [0, 0.5), got {self.touch_margin}")
        if self.touch_dwells < 1:
            raise EctskinError(f"protocol: touch_dwells must be >= 1, got {self.touch_dwells}")
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
        for k in ("levels_ml", "force_range_n"):
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
                m = protocol.touch_margin
                du, dv = reg.u_mm[1] - reg.u_mm[0], reg.v_mm[1] - reg.v_mm[0]
                lo = np.array([reg.u_mm[0] + m * du, reg.v_mm[0] + m * dv])
                hi = np.array([reg.u_mm[1] - m * du, reg.v_mm[1] - m * dv])
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
