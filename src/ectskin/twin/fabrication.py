"""Fabrication variability: the skin that comes out of the mould, sampled around the nominal one.

A lab casts, fills and bonds a skin from a layout file; what it gets differs from the file. A
:class:`FabricationVariation` holds the spreads (all **(assumed)**, set per lab), and
:func:`sample_skin` draws one :class:`FabricatedSkin` from them with a seed:

==================  ======================================================================
wire position       each electrode (wire and pad together) moved across the face (u) by
                    δ ~ N(0, σ²), ``wire_position_sigma_mm`` (assumed 0.5 mm), clipped at ±2σ
wire width          each wire's width × (1 + r), r ~ U(−a, a), ``width_rel`` (assumed 0.2)
permittivity        the silicone's effective ε_r × (1 + r), ``eps_rel`` (assumed 0.05): one
                    cast, one batch of silicone, one value for the whole body
thickness           the body's thickness (``ManipulatorConfig.thickness_mm``) × (1 + r),
                    ``thickness_rel`` (assumed 0.10)
bonding offset      each skin (its rectangle, wires and pads) shifted on the body by
                    (du, dv) ~ U(−b, b)², ``bonding_offset_mm`` (assumed 1 mm) per skin
fault               ``"none"``, ``"dead"`` (one electrode drawn at random has an open wire) or
                    ``"short"`` (two neighbouring electrodes of one skin drawn at random touch)
==================  ======================================================================

What stays: the touch regions and the markers are marked on the *body*, so they do not move
with a skin's bonding offset; the experimenter touches the body where the nominal layout says.
The recording a fabricated skin gives (:func:`simulate_skin`) therefore carries the *nominal*
layout (what the lab believes it built), and the skin as built in ``meta["fabrication"]``.

Faults act at the readout (:func:`apply_fault`), on the recorded values:

* **dead** electrode k (an open wire: the meter sees nothing behind the break): every pair with
  k reads what the electronics read for C = 0, the averaged quantisation noise alone
  (:func:`~ectskin.twin.readout.readout` of zeros). The broken wire stays in the field as
  floating metal; its small effect on the other pairs is left out.
* **short** between electrodes i and j: the two are one conductor at one potential. By
  superposition (the Maxwell matrix K is linear in the potentials) exciting the merged conductor
  and reading electrode k gives C_Mk = C_ik + C_jk, exactly, so both pairs (i, k) and (j, k)
  read that sum (checked against a method-of-moments solve of the merged conductor in the tests).
  The pair (i, j) itself excites its own receiver: no mutual capacitance is measured, and it
  reads like a dead pair (the readout of C = 0; a real meter may saturate instead). The sum is
  taken of the two recorded channels, so it carries both channels' gain noise and drift, a
  √2 on noise at the readout's > 60 dB: negligible next to the sum itself.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.io.recording import Recording
from ectskin.layout import SensorLayout
from ectskin.twin.mechanics import ManipulatorConfig
from ectskin.twin.protocol import Protocol
from ectskin.twin.readout import ReadoutConfig, readout
from ectskin.twin.simulate import simulate_experiment

log = logging.getLogger(__name__)

#: The fault cases of a fabricated skin.
FAULTS = ("none", "dead", "short")
#: Wire shifts are drawn from a normal distribution clipped at this many σ (a wire far off its
#: line would be seen at the bench and the skin recast).
POSITION_CLIP_SIGMA = 2.0


@dataclass(frozen=True)
class FabricationVariation:
    """The spreads of one fabrication process (module docstring; every default **assumed**).

    ``wire_position_sigma_mm``: σ of each electrode's shift across its face (mm); ``width_rel``,
    ``eps_rel``, ``thickness_rel``: half-widths of the uniform relative spreads of the wire
    width, the silicone's permittivity and the body's thickness; ``bonding_offset_mm``: half-width
    of each skin's uniform offset on the body in u and in v (mm); ``fault``: "none", "dead" or
    "short".
    """

    wire_position_sigma_mm: float = 0.5
    width_rel: float = 0.2
    eps_rel: float = 0.05
    thickness_rel: float = 0.10
    bonding_offset_mm: float = 1.0
    fault: str = "none"

    def __post_init__(self) -> None:
        for name in (
            "wire_position_sigma_mm",
            "width_rel",
            "eps_rel",
            "thickness_rel",
            "bonding_offset_mm",
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v) or v < 0:
                raise EctskinError(
                    f"fabrication variation: {name} must be a finite number >= 0, got {v!r}"
                )
        for name in ("width_rel", "eps_rel", "thickness_rel"):
            if getattr(self, name) >= 1:
                raise EctskinError(
                    f"fabrication variation: {name} must be < 1 (a relative spread; 1 would allow "
                    f"a zero width, permittivity or thickness), got {getattr(self, name)!r}"
                )
        check_option("fault", self.fault, FAULTS, source="fabrication variation")

    @classmethod
    def none(cls) -> FabricationVariation:
        """No variation and no fault: :func:`sample_skin` returns the nominal skin."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, "none")

    def scaled(self, factor: float) -> FabricationVariation:
        """Every spread × ``factor`` (the fault unchanged): the x-axis of a degradation curve."""
        if not (np.isfinite(factor) and factor >= 0):
            raise EctskinError(f"fabrication variation: scale must be >= 0, got {factor!r}")
        return replace(
            self,
            wire_position_sigma_mm=self.wire_position_sigma_mm * factor,
            width_rel=min(self.width_rel * factor, 0.9),
            eps_rel=min(self.eps_rel * factor, 0.9),
            thickness_rel=min(self.thickness_rel * factor, 0.9),
            bonding_offset_mm=self.bonding_offset_mm * factor,
        )


@dataclass(frozen=True)
class Fault:
    """A fault of a fabricated skin: ``kind`` "dead" (one electrode index) or "short" (two)."""

    kind: str
    electrodes: tuple[int, ...]

    def __post_init__(self) -> None:
        check_option("fault kind", self.kind, ("dead", "short"), source="fault")
        want = 1 if self.kind == "dead" else 2
        if len(self.electrodes) != want or len(set(self.electrodes)) != want:
            raise EctskinError(
                f"fault: a {self.kind!r} fault names {want} distinct electrode(s), got "
                f"{self.electrodes!r}"
            )


@dataclass(frozen=True)
class FabricatedSkin:
    """One skin as built: the perturbed layout, permittivity, body and fault, with the draws.

    ``layout``: the electrodes where they really are (shifted, widened, skins offset);
    ``nominal``: the layout file it was made from; ``eps_r``: the silicone's effective relative
    permittivity; ``manipulator``: the body (its thickness perturbed); ``wire_shift_mm``,
    ``width_scale``: (n_electrodes,) draws; ``offsets_mm``: skin name → (du, dv) mm; ``fault``:
    None or a :class:`Fault`; ``seed``: the draw's seed.
    """

    nominal: SensorLayout
    layout: SensorLayout
    eps_r: float
    manipulator: ManipulatorConfig
    wire_shift_mm: np.ndarray
    width_scale: np.ndarray
    offsets_mm: dict[str, tuple[float, float]]
    fault: Fault | None = None
    seed: int = 0
    variation: FabricationVariation = field(default_factory=FabricationVariation)

    def to_dict(self) -> dict[str, Any]:
        """What was drawn, JSON-able (stored in the recording's ``meta["fabrication"]``)."""
        return {
            "seed": int(self.seed),
            "variation": asdict(self.variation),
            "eps_r": float(self.eps_r),
            "thickness_mm": float(self.manipulator.thickness_mm),
            "wire_shift_mm": [float(v) for v in self.wire_shift_mm],
            "width_scale": [float(v) for v in self.width_scale],
            "offsets_mm": {k: [float(v[0]), float(v[1])] for k, v in self.offsets_mm.items()},
            "fault": None
            if self.fault is None
            else {"kind": self.fault.kind, "electrodes": list(self.fault.electrodes)},
        }


def perturb_layout(
    layout: SensorLayout,
    wire_shift_mm: np.ndarray,
    width_scale: np.ndarray,
    offsets_mm: dict[str, tuple[float, float]],
) -> SensorLayout:
    """The layout with each electrode k (wire and pad) moved by ``wire_shift_mm[k]`` in u, its
    wire width × ``width_scale[k]``, and each skin (rectangle, wires, pads) moved by
    ``offsets_mm[skin]`` = (du, dv) mm. Regions and markers stay (they are on the body).

    Validated like a layout file: a perturbation that puts a wire outside its skin or onto
    another is an :class:`EctskinError`.
    """
    n = layout.n_electrodes
    shift = np.asarray(wire_shift_mm, dtype=np.float64)
    scale = np.asarray(width_scale, dtype=np.float64)
    if shift.shape != (n,) or scale.shape != (n,):
        raise EctskinError(
            f"perturb_layout: wire_shift_mm and width_scale must hold one value per electrode "
            f"({n}), got shapes {shift.shape} and {scale.shape}"
        )
    if not (np.all(np.isfinite(scale)) and np.all(scale > 0)):
        raise EctskinError(f"perturb_layout: width_scale must be > 0, got {scale.tolist()}")
    unknown = set(offsets_mm) - {s.name for s in layout.skins}
    if unknown:
        raise EctskinError(
            f"perturb_layout: offsets_mm names unknown skin(s) {sorted(unknown)}; layout "
            f"{layout.name!r} has {[s.name for s in layout.skins]}"
        )
    d = layout.to_dict()
    for s in d["skins"]:
        du, dv = offsets_mm.get(s["name"], (0.0, 0.0))
        s["u_mm"] = [s["u_mm"][0] + du, s["u_mm"][1] + du]
        s["v_mm"] = [s["v_mm"][0] + dv, s["v_mm"][1] + dv]
    for k, e in enumerate(d["electrodes"]):
        du, dv = offsets_mm.get(e["skin"], (0.0, 0.0))
        move = np.array([du + shift[k], dv])
        e["polyline_mm"] = (np.asarray(e["polyline_mm"], dtype=np.float64) + move).tolist()
        c = e["pad"]["centre_mm"]
        e["pad"]["centre_mm"] = [c[0] + move[0], c[1] + move[1]]
        e["width_mm"] = e["width_mm"] * scale[k]
    return SensorLayout.from_dict(d, source=f"layout {layout.name!r} as fabricated")


def neighbour_pairs(layout: SensorLayout) -> list[tuple[int, int]]:
    """Electrode pairs (i, j), i < j, that are neighbours on one skin: j is the electrode whose
    pad is nearest to i's on the same skin, or the other way round. These can short."""
    pads = np.array([e.pad_centre_mm for e in layout.electrodes], dtype=np.float64)
    out = set()
    for i, e in enumerate(layout.electrodes):
        same = [j for j, f in enumerate(layout.electrodes) if j != i and f.skin == e.skin]
        if same:
            j = min(same, key=lambda j: float(np.linalg.norm(pads[j] - pads[i])))
            out.add((min(i, j), max(i, j)))
    return sorted(out)


def sample_skin(
    nominal_layout: SensorLayout,
    variation: FabricationVariation,
    seed: int,
    *,
    eps_r: float = 2.0,
    manipulator: ManipulatorConfig | None = None,
) -> FabricatedSkin:
    """Draw one fabricated skin from ``variation`` with ``seed`` (module docstring).

    ``eps_r`` and ``manipulator`` are the nominal permittivity and body. Every draw is taken
    whatever the spreads, from one generator, so a spread of zero leaves the others' draws as
    they were, and zero spreads return the nominal values exactly.
    """
    if not isinstance(variation, FabricationVariation):
        raise EctskinError(
            f"sample_skin: variation must be a FabricationVariation, got {type(variation).__name__}"
        )
    manipulator = manipulator or ManipulatorConfig()
    rng = np.random.default_rng([int(seed), 11])
    n = nominal_layout.n_electrodes
    sigma = variation.wire_position_sigma_mm
    z = np.clip(rng.standard_normal(n), -POSITION_CLIP_SIGMA, POSITION_CLIP_SIGMA)
    shift = sigma * z
    width_scale = 1.0 + variation.width_rel * rng.uniform(-1.0, 1.0, n)
    eps = eps_r * (1.0 + variation.eps_rel * rng.uniform(-1.0, 1.0))
    thick = manipulator.thickness_mm * (1.0 + variation.thickness_rel * rng.uniform(-1.0, 1.0))
    offsets: dict[str, tuple[float, float]] = {}
    for s in nominal_layout.skins:
        du, dv = variation.bonding_offset_mm * rng.uniform(-1.0, 1.0, 2)
        offsets[s.name] = (float(du), float(dv))
    fault = _draw_fault(nominal_layout, variation.fault, rng)
    try:
        layout = perturb_layout(nominal_layout, shift, width_scale, offsets)
    except EctskinError as exc:
        raise EctskinError(
            f"sample_skin (seed {seed}): the drawn skin is not a valid layout ({exc}); lower "
            f"the spreads of the fabrication variation"
        ) from None
    return FabricatedSkin(
        nominal=nominal_layout,
        layout=layout,
        eps_r=float(eps),
        manipulator=replace(manipulator, thickness_mm=float(thick)),
        wire_shift_mm=shift,
        width_scale=width_scale,
        offsets_mm=offsets,
        fault=fault,
        seed=int(seed),
        variation=variation,
    )


def _draw_fault(layout: SensorLayout, kind: str, rng: np.random.Generator) -> Fault | None:
    """A dead electrode or a shorted neighbour pair drawn uniformly (always drawn, so the
    fault choice never shifts the other draws)."""
    k = int(rng.integers(layout.n_electrodes))
    pairs = neighbour_pairs(layout)
    m = int(rng.integers(len(pairs))) if pairs else -1
    if kind == "dead":
        return Fault("dead", (k,))
    if kind == "short":
        if not pairs:
            raise EctskinError(
                f"fabrication variation: fault 'short' needs two electrodes on one skin; layout "
                f"{layout.name!r} has none"
            )
        return Fault("short", pairs[m])
    return None


# ------------------------------------------------------------------------------ readout faults
def fault_channels(layout: SensorLayout, fault: Fault) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The channels a fault touches, as pair indices in the layout's pair order: the dead ones,
    and for a short the (pair (i, k), pair (j, k)) couples that both read their sum (the pair
    (i, j) itself is dead)."""
    pairs = layout.pairs
    index = {(int(a), int(b)): p for p, (a, b) in enumerate(pairs)}
    n = layout.n_electrodes
    for e in fault.electrodes:
        if not 0 <= e < n:
            raise EctskinError(f"fault: electrode {e} does not exist (layout has {n})")
    if fault.kind == "dead":
        k = fault.electrodes[0]
        return np.flatnonzero((pairs[:, 0] == k) | (pairs[:, 1] == k)), []
    i, j = sorted(fault.electrodes)
    merged = []
    for k in range(n):
        if k in (i, j):
            continue
        a, b = index[(min(i, k), max(i, k))], index[(min(j, k), max(j, k))]
        merged.append((a, b))
    return np.array([index[(i, j)]]), merged


def apply_fault_true(capacitance: np.ndarray, layout: SensorLayout, fault: Fault) -> np.ndarray:
    """The fault on true capacitances (F, n_pairs) pF, no electronics: dead pairs read 0, a
    short's pairs (i, k) and (j, k) both read C_ik + C_jk (module docstring)."""
    c = np.array(capacitance, dtype=np.float64, copy=True)
    dead, merged = fault_channels(layout, fault)
    for a, b in merged:
        s = c[..., a] + c[..., b]
        c[..., a] = s
        c[..., b] = s
    c[..., dead] = 0.0
    return c


def apply_fault(rec: Recording, fault: Fault | None, config: ReadoutConfig, seed: int) -> Recording:
    """``rec`` with ``fault`` applied at the readout (module docstring): the recorded channels
    of a short summed, dead channels replaced by the electronics' reading of C = 0 (noise from
    a stream seeded by (``seed``, trial index)). None returns ``rec`` unchanged."""
    if fault is None:
        return rec
    dead, merged = fault_channels(rec.layout, fault)
    trials = []
    for idx, t in enumerate(rec.trials):
        c = np.array(t.capacitance, dtype=np.float64, copy=True)
        for a, b in merged:
            s = c[:, a] + c[:, b]
            c[:, a] = s
            c[:, b] = s
        if dead.size:
            rng = np.random.default_rng([int(seed), 13, idx])
            zero = np.zeros((t.n_frames, dead.size))
            c[:, dead] = readout(zero, t.timestamps, rng, config, np.zeros(dead.size))
        trials.append(replace(t, capacitance=c, meta=dict(t.meta)))
    meta = dict(rec.meta)
    meta["fault"] = {"kind": fault.kind, "electrodes": list(fault.electrodes)}
    return Recording(layout=rec.layout, trials=trials, frame_rate_hz=rec.frame_rate_hz, meta=meta)


# ------------------------------------------------------------------------------ simulation
def simulate_skin(
    protocol: Protocol,
    skin: FabricatedSkin,
    *,
    workers: int | None = None,
    progress: bool = True,
    **kwargs: Any,
) -> Recording:
    """Simulate ``protocol`` with the skin as built, faults applied at the readout.

    The twin (:func:`~ectskin.twin.simulate.simulate_experiment`) runs with the fabricated
    layout, permittivity and body; ``kwargs`` go to it (``discretisation``, ``chamber_eps_r``).
    The recording carries the *nominal* layout (what the lab believes it built: the region
    labels and the channel names are the nominal ones) and ``meta["fabrication"]``.
    """
    rec = simulate_experiment(
        protocol,
        layout=skin.layout,
        manipulator=skin.manipulator,
        eps_r=skin.eps_r,
        workers=workers,
        progress=progress,
        **kwargs,
    )
    meta = dict(rec.meta)
    meta["fabrication"] = skin.to_dict()
    rec = Recording(
        layout=skin.nominal, trials=list(rec.trials), frame_rate_hz=rec.frame_rate_hz, meta=meta
    )
    return apply_fault(rec, skin.fault, protocol.readout, skin.seed)


def nominal_skin(
    layout: SensorLayout, *, eps_r: float = 2.0, manipulator: ManipulatorConfig | None = None
) -> FabricatedSkin:
    """The skin exactly as designed (no variation, no fault)."""
    return sample_skin(layout, FabricationVariation.none(), 0, eps_r=eps_r, manipulator=manipulator)


def with_fault(skin: FabricatedSkin, fault: Fault | None) -> FabricatedSkin:
    """The same skin with another fault (or none)."""
    return replace(skin, fault=fault)


__all__ = [
    "FAULTS",
    "FabricatedSkin",
    "FabricationVariation",
    "Fault",
    "apply_fault",
    "apply_fault_true",
    "fault_channels",
    "neighbour_pairs",
    "nominal_skin",
    "perturb_layout",
    "sample_skin",
    "simulate_skin",
    "with_fault",
]
