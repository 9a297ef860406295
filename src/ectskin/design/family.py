"""A parameterised family of wire layouts and the manufacturing rules every layout must meet.

A :class:`FaceDesign` describes the wires of one face (front or back) of the paper's skins:

* ``n_wires`` straight wires along v, their x positions evenly spread over ``span_mm``;
* wire lengths (the part above the pads, mm) linear from ``length_min_mm`` to
  ``length_max_mm``, assigned to the wires by ``order`` (``ascending``: left to right,
  ``descending``, ``outside_in``: the outer wires shortest, ``inside_out``: the outer wires
  longest);
* ``routing`` of the leads to the pads at the base: ``straight`` (each pad directly below its
  wire, the paper's) or ``fan`` (the pads evenly across the base, each lead rising
  ``FAN_STRAIGHT_MM`` and then running diagonally over ``FAN_RISE_MM`` to its wire's x);
* ``width_mm``, the wire width.

:func:`build_layout` turns a :class:`LayoutDesign` (front and back faces) into a
:class:`~ectskin.layout.SensorLayout` with the paper's skins, touch regions and markers, so any
layout of the family runs through the same protocol and is scored on the same touches. The
paper's layout is a member: 4 wires per face over 30 mm, 20 to 95 mm ascending, straight, 1 mm.

:class:`ManufacturingRules` are what a mould can make (all assumed defaults): a minimum wire
width, a minimum gap between conductors on one face, every wire inside its skin with a margin.
:func:`check_manufacturable` refuses a layout that violates them with one
:class:`~ectskin._check.EctskinError` naming the layout's file and the field.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.layout import Electrode, SensorLayout, default_layout
from ectskin.layout.geometry import polyline_distance, sample_polyline

ORDERS = ("ascending", "descending", "outside_in", "inside_out")
ROUTINGS = ("straight", "fan")
FACES = ("front", "back")
MAX_PAD_MM = 5.0  # the paper's 5 x 5 mm pads
MIN_PAD_MM = 2.0  # (assumed) the smallest pad a readout lead can be bonded to
FAN_STRAIGHT_MM = 2.0  # (assumed) a fanned lead leaves its pad straight for this long
FAN_RISE_MM = 10.0  # (assumed) ... then runs diagonally over this height to its wire's x


@dataclass(frozen=True)
class ManufacturingRules:
    """What the mould can make (assumed defaults, mm).

    min_width_mm : the narrowest wire a liquid-metal channel can be moulded and filled.
    min_spacing_mm : the smallest gap between two conductors (wires or pads) on one face.
    edge_margin_mm : every wire lies at least this far inside its skin's rectangle (pads sit at
        the base edge, where the leads leave the skin; the loader keeps them on the skin).
    """

    min_width_mm: float = 0.5
    min_spacing_mm: float = 1.0
    edge_margin_mm: float = 0.0

    def __post_init__(self) -> None:
        for name in ("min_width_mm", "min_spacing_mm", "edge_margin_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise EctskinError(f"manufacturing rules: {name} must be a number >= 0, got {v!r}")


def check_manufacturable(layout: SensorLayout, rules: ManufacturingRules | None = None) -> None:
    """Raise :class:`EctskinError` naming the file (``layout.source``) and the electrode field
    when ``layout`` breaks a manufacturing rule; return None when it meets them all."""
    rules = rules or ManufacturingRules()
    src = layout.source or f"layout {layout.name!r}"
    skins = {s.name: s for s in layout.skins}
    for k, e in enumerate(layout.electrodes):
        if e.width_mm < rules.min_width_mm:
            raise EctskinError(
                f"{src}: electrodes[{k}].width_mm: electrode {e.name!r} is {e.width_mm:g} mm wide; "
                f"the mould needs at least {rules.min_width_mm:g} mm (min_width_mm)"
            )
        sk = skins[e.skin]
        pts = e.outline_points()[:-4]  # the wire's corners (the last four are the pad's)
        m = rules.edge_margin_mm
        lo = np.array([sk.u_mm[0] + m, sk.v_mm[0] + m])
        hi = np.array([sk.u_mm[1] - m, sk.v_mm[1] - m])
        bad = np.any((pts < lo - 1e-9) | (pts > hi + 1e-9), axis=1)
        if bad.any():
            p = pts[np.argmax(bad)]
            raise EctskinError(
                f"{src}: electrodes[{k}].polyline_mm: the wire of {e.name!r} reaches "
                f"({p[0]:.2f}, {p[1]:.2f}) mm, outside its skin {e.skin!r} less the "
                f"{m:g} mm edge margin (u {lo[0]:g}..{hi[0]:g}, v {lo[1]:g}..{hi[1]:g} mm)"
            )
    surf = [skins[e.skin].surface for e in layout.electrodes]
    for a, ea in enumerate(layout.electrodes):
        for b in range(a + 1, len(layout.electrodes)):
            eb = layout.electrodes[b]
            if surf[a] != surf[b]:
                continue
            gap = conductor_gap_mm(ea, eb)
            if gap < rules.min_spacing_mm - 1e-9:
                raise EctskinError(
                    f"{src}: electrodes[{b}].polyline_mm: electrodes {ea.name!r} and {eb.name!r} "
                    f"are {gap:.2f} mm apart on surface {surf[a]!r}; the mould needs a gap of at "
                    f"least {rules.min_spacing_mm:g} mm (min_spacing_mm)"
                )


def conductor_gap_mm(a: Electrode, b: Electrode) -> float:
    """The smallest edge-to-edge gap between two electrodes (wires and pads), mm.

    Wire to wire: centre-line distance less half of each width; a pad is its rectangle
    (distance from a sampled centre line to the rectangle, less half the width; rectangle to
    rectangle by their axis gaps). Negative when they overlap.
    """
    pa = sample_polyline(a.polyline_mm, step_mm=0.1)
    pb = sample_polyline(b.polyline_mm, step_mm=0.1)
    gaps = [polyline_distance(pa, b.polyline_mm) - (a.width_mm + b.width_mm) / 2]
    gaps.append(_rect_distance(pb, a.pad_centre_mm, a.pad_size_mm) - b.width_mm / 2)
    gaps.append(_rect_distance(pa, b.pad_centre_mm, b.pad_size_mm) - a.width_mm / 2)
    dx = abs(a.pad_centre_mm[0] - b.pad_centre_mm[0]) - (a.pad_size_mm[0] + b.pad_size_mm[0]) / 2
    dy = abs(a.pad_centre_mm[1] - b.pad_centre_mm[1]) - (a.pad_size_mm[1] + b.pad_size_mm[1]) / 2
    gaps.append(float(np.hypot(max(dx, 0.0), max(dy, 0.0))) if max(dx, dy) > 0 else max(dx, dy))
    return float(min(gaps))


def _rect_distance(points: np.ndarray, centre, size) -> float:
    """Smallest distance from ``points`` (n, 2) to an axis-aligned rectangle (0 inside)."""
    d = np.abs(points - np.asarray(centre)) - np.asarray(size) / 2
    return float(np.min(np.linalg.norm(np.maximum(d, 0.0), axis=1)))


@dataclass(frozen=True)
class FaceDesign:
    """The wires of one face (see the module docstring); lengths and positions in mm."""

    n_wires: int = 4
    span_mm: float = 30.0
    length_min_mm: float = 20.0
    length_max_mm: float = 95.0
    order: str = "ascending"
    routing: str = "straight"
    width_mm: float = 1.0

    def __post_init__(self) -> None:
        check_option("order", self.order, ORDERS)
        check_option("routing", self.routing, ROUTINGS)
        if not isinstance(self.n_wires, (int, np.integer)) or self.n_wires < 2:
            raise EctskinError(
                f"face design: n_wires must be an integer >= 2, got {self.n_wires!r}"
            )
        if not (0 < self.length_min_mm <= self.length_max_mm):
            raise EctskinError(
                f"face design: need 0 < length_min_mm <= length_max_mm, got "
                f"{self.length_min_mm!r}, {self.length_max_mm!r}"
            )


@dataclass(frozen=True)
class LayoutDesign:
    """A member of the family: one :class:`FaceDesign` per face."""

    front: FaceDesign = field(default_factory=FaceDesign)
    back: FaceDesign = field(default_factory=FaceDesign)

    @property
    def n_electrodes(self) -> int:
        return self.front.n_wires + self.back.n_wires

    def to_dict(self) -> dict[str, Any]:
        return {"front": asdict(self.front), "back": asdict(self.back)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LayoutDesign:
        return cls(FaceDesign(**d["front"]), FaceDesign(**d["back"]))


def _lengths(face: FaceDesign) -> np.ndarray:
    """Wire lengths, left to right (mm)."""
    n = face.n_wires
    ladder = np.linspace(face.length_min_mm, face.length_max_mm, n)
    x_rank = np.arange(n)
    if face.order == "ascending":
        rank = x_rank
    elif face.order == "descending":
        rank = x_rank[::-1]
    else:  # by distance from the centre: outer wires first (outside_in) or last
        dist = np.abs(x_rank - (n - 1) / 2)
        by = np.argsort(-dist if face.order == "outside_in" else dist, kind="stable")
        rank = np.empty(n, dtype=int)
        rank[by] = np.arange(n)
    return ladder[rank]


def face_electrodes(
    face: FaceDesign, skin, first_index: int, rules: ManufacturingRules | None = None
) -> list[Electrode]:
    """The electrodes ``E<first_index>``… of ``face`` on ``skin`` (a :class:`Skin`); pads are
    as large as ``rules.min_spacing_mm`` between them allows, at most ``MAX_PAD_MM``."""
    gap = (rules or ManufacturingRules()).min_spacing_mm
    n = face.n_wires
    u0, u1 = skin.u_mm
    v0, v1 = skin.v_mm
    xs = np.round(np.linspace(-face.span_mm / 2, face.span_mm / 2, n) + (u0 + u1) / 2, 4)
    if face.routing == "straight":
        pitch = face.span_mm / (n - 1)
        pad = min(MAX_PAD_MM, pitch - gap)
        pad_x = xs
    else:
        pad = min(MAX_PAD_MM, (u1 - u0 - (n + 1) * gap) / n)
        pad_x = np.linspace(u0 + gap + pad / 2, u1 - gap - pad / 2, n)
    if pad < MIN_PAD_MM:
        raise EctskinError(
            f"face design: {n} wires with {face.routing!r} routing over {u1 - u0:g} mm leave "
            f"pads of {pad:.2f} mm; at least {MIN_PAD_MM:g} mm are needed (fewer wires, a wider "
            f"span or fan routing)"
        )
    pad = float(np.floor(pad * 1e4) / 1e4)  # 0.1 µm steps: the file's numbers are exact
    v_start = v0 + pad
    out = []
    for k, (x, px, length) in enumerate(zip(xs, pad_x, _lengths(face))):
        v_end = v_start + length
        if face.routing == "fan" and abs(px - x) > 1e-9:
            knee = v_start + FAN_STRAIGHT_MM
            top = knee + FAN_RISE_MM
            if v_end <= top:
                raise EctskinError(
                    f"face design: a fanned wire of {length:g} mm does not reach past its "
                    f"{FAN_STRAIGHT_MM + FAN_RISE_MM:g} mm lead"
                )
            poly = [[px, v_start], [px, knee], [x, top], [x, v_end]]
        else:
            poly = [[x, v_start], [x, v_end]]
        out.append(
            Electrode(
                name=f"E{first_index + k}",
                skin=skin.name,
                polyline_mm=np.asarray(poly, dtype=np.float64),
                width_mm=float(face.width_mm),
                pad_centre_mm=(round(float(px), 6), v0 + pad / 2),
                pad_size_mm=(float(pad), float(pad)),
            )
        )
    return out


def build_layout(
    design: LayoutDesign,
    name: str,
    *,
    base: SensorLayout | None = None,
    rules: ManufacturingRules | None = None,
) -> SensorLayout:
    """The layout of ``design`` on ``base``'s skins (default the paper's), with its regions and
    markers, validated by the layout loader and by :func:`check_manufacturable`."""
    base = base or default_layout()
    skins = {s.surface: s for s in base.skins}
    electrodes: list[Electrode] = []
    for face in FACES:
        if face not in skins:
            raise EctskinError(f"layout {base.name!r} has no skin on the {face} face")
        electrodes += face_electrodes(
            getattr(design, face), skins[face], len(electrodes) + 1, rules
        )
    layout = replace(base, name=name, electrodes=tuple(electrodes), source=None)
    layout = SensorLayout.from_dict(layout.to_dict(), source=f"design {name!r}")
    check_manufacturable(layout, rules)
    return layout
