"""The e-skin layout as data: skins, electrodes (wire polylines with pads), pairs, regions, markers.

Surfaces are the faces of the manipulator body, addressed by surface coordinates in mm:

==========  ====================  ==========================
surface     rest position         surface coordinates (u, v)
==========  ====================  ==========================
``front``   y = +thickness/2      (x, z)
``back``    y = -thickness/2      (x, z)
``right``   x = +width/2          (y, z)
``left``    x = -width/2          (y, z)
==========  ====================  ==========================

z runs from the clamped base (z = 0) to the tip. A layout is validated once, when built: names are
unique, every electrode (wire and pad) lies inside its skin, wires on one skin do not overlap, and
regions and markers lie on known surfaces.

Pairs follow the fixed ECT order (1,2),(1,3)…(1,n),(2,3)…(n-1,n) over electrodes in file order, so
8 electrodes give 28 pairs. :meth:`SensorLayout.electrode_descriptors` gives the per-electrode
features from which the models build the pair embeddings P and Q.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout.geometry import pad_touches, polyline_distance, sample_polyline

SURFACES = ("front", "back", "right", "left")
LAYOUT_SCHEMA = "ectskin.layout"
LAYOUT_VERSION = 1


@dataclass(frozen=True)
class Skin:
    """One e-skin module: a rectangle ``u_mm`` × ``v_mm`` (ranges) on ``surface``."""

    name: str
    surface: str
    u_mm: tuple[float, float]
    v_mm: tuple[float, float]

    def contains(self, uv: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        uv = np.atleast_2d(uv)
        return (
            (uv[:, 0] >= self.u_mm[0] - tol)
            & (uv[:, 0] <= self.u_mm[1] + tol)
            & (uv[:, 1] >= self.v_mm[0] - tol)
            & (uv[:, 1] <= self.v_mm[1] + tol)
        )


@dataclass(frozen=True)
class Electrode:
    """A liquid-metal wire electrode: a polyline (surface coordinates, mm) of ``width_mm``.

    The pad is a ``pad_size_mm`` rectangle centred at ``pad_centre_mm``; it is part of the same
    conductor (the interface to the readout).
    """

    name: str
    skin: str
    polyline_mm: np.ndarray  # (n_points, 2) surface coordinates (u, v)
    width_mm: float
    pad_centre_mm: tuple[float, float]
    pad_size_mm: tuple[float, float]

    @property
    def length_mm(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.polyline_mm, axis=0), axis=1)))

    def outline_points(self) -> np.ndarray:
        """Corner points of the wire (offset by half the width) and of the pad, (n, 2) mm."""
        pts = []
        h = self.width_mm / 2
        for a, b in zip(self.polyline_mm[:-1], self.polyline_mm[1:]):
            t = (b - a) / np.linalg.norm(b - a)
            nrm = np.array([-t[1], t[0]])
            for p in (a - t * h, b + t * h):
                pts += [p + nrm * h, p - nrm * h]
        c = np.asarray(self.pad_centre_mm)
        s = np.asarray(self.pad_size_mm) / 2
        pts += [c + s * np.array(sg) for sg in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
        return np.asarray(pts)


@dataclass(frozen=True)
class Region:
    """A touch region (class ``id`` ≥ 1): a rectangle of surface coordinates on ``surface``."""

    id: int
    surface: str
    u_mm: tuple[float, float]
    v_mm: tuple[float, float]

    @property
    def centre_mm(self) -> tuple[float, float]:
        return ((self.u_mm[0] + self.u_mm[1]) / 2, (self.v_mm[0] + self.v_mm[1]) / 2)


@dataclass(frozen=True)
class Marker:
    """A motion-capture marker at surface coordinates ``uv_mm`` on ``surface``."""

    name: str
    surface: str
    uv_mm: tuple[float, float]


@dataclass(frozen=True)
class SensorLayout:
    """Skins, electrodes, touch regions and markers of one e-skin system.

    Built through :func:`load_layout` / :meth:`from_dict`, which validate. Derived counts are
    exposed as ``n_electrodes``, ``n_pairs``, ``n_regions``, ``n_markers``.
    """

    name: str
    skins: tuple[Skin, ...]
    electrodes: tuple[Electrode, ...]
    regions: tuple[Region, ...]
    markers: tuple[Marker, ...]
    source: str | None = field(default=None, compare=False)

    # ----------------------------------------------------------------- derived
    @property
    def n_electrodes(self) -> int:
        return len(self.electrodes)

    @property
    def n_pairs(self) -> int:
        return self.n_electrodes * (self.n_electrodes - 1) // 2

    @property
    def n_regions(self) -> int:
        return len(self.regions)

    @property
    def n_classes(self) -> int:
        """Touch classes: 0 (no touch) plus one per region."""
        return self.n_regions + 1

    @property
    def n_markers(self) -> int:
        return len(self.markers)

    @cached_property
    def pairs(self) -> np.ndarray:
        """(n_pairs, 2) electrode indices (0-based) in the fixed order (0,1),(0,2)…(n-2,n-1)."""
        i, j = np.triu_indices(self.n_electrodes, k=1)
        return np.stack([i, j], axis=1)

    @cached_property
    def pair_names(self) -> tuple[str, ...]:
        names = [e.name for e in self.electrodes]
        return tuple(f"{names[i]}-{names[j]}" for i, j in self.pairs)

    def skin(self, name: str) -> Skin:
        for s in self.skins:
            if s.name == name:
                return s
        raise EctskinError(f"layout {self.name!r}: no skin named {name!r}")

    def electrode_surface(self, index: int) -> str:
        return self.skin(self.electrodes[index].skin).surface

    @cached_property
    def same_surface(self) -> np.ndarray:
        """(n_pairs,) bool: both electrodes of the pair lie on the same surface."""
        surf = [self.electrode_surface(k) for k in range(self.n_electrodes)]
        return np.array([surf[i] == surf[j] for i, j in self.pairs])

    def region(self, region_id: int) -> Region:
        for r in self.regions:
            if r.id == region_id:
                return r
        ids = ", ".join(str(r.id) for r in self.regions)
        raise EctskinError(f"unknown region {region_id!r}: layout {self.name!r} has regions {ids}")

    def electrode_descriptors(self) -> np.ndarray:
        """(n_electrodes, 6) features for the P/Q pair embeddings of the models.

        Columns: wire centroid u, v (mm, /100), surface side (+1 front, -1 back, 0 other),
        length (mm, /100), width (mm), pad centre v (mm, /100). Scaled to order one.
        """
        side = {"front": 1.0, "back": -1.0}
        rows = []
        for k, e in enumerate(self.electrodes):
            seg = np.diff(e.polyline_mm, axis=0)
            seg_len = np.linalg.norm(seg, axis=1)
            mids = (e.polyline_mm[:-1] + e.polyline_mm[1:]) / 2
            centroid = (mids * seg_len[:, None]).sum(0) / max(seg_len.sum(), 1e-12)
            rows.append(
                [
                    centroid[0] / 100,
                    centroid[1] / 100,
                    side.get(self.electrode_surface(k), 0.0),
                    e.length_mm / 100,
                    e.width_mm,
                    e.pad_centre_mm[1] / 100,
                ]
            )
        return np.asarray(rows, dtype=np.float64)

    # --------------------------------------------------------------- (de)serialise
    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": LAYOUT_SCHEMA,
            "version": LAYOUT_VERSION,
            "name": self.name,
            "skins": [
                {"name": s.name, "surface": s.surface, "u_mm": list(s.u_mm), "v_mm": list(s.v_mm)}
                for s in self.skins
            ],
            "electrodes": [
                {
                    "name": e.name,
                    "skin": e.skin,
                    "polyline_mm": e.polyline_mm.tolist(),
                    "width_mm": e.width_mm,
                    "pad": {"centre_mm": list(e.pad_centre_mm), "size_mm": list(e.pad_size_mm)},
                }
                for e in self.electrodes
            ],
            "regions": [
                {"id": r.id, "surface": r.surface, "u_mm": list(r.u_mm), "v_mm": list(r.v_mm)}
                for r in self.regions
            ],
            "markers": [
                {"name": m.name, "surface": m.surface, "uv_mm": list(m.uv_mm)} for m in self.markers
            ],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    @classmethod
    def from_dict(cls, d: Any, source: str | None = None) -> SensorLayout:
        return _parse_layout(d, source)

    @classmethod
    def from_json(cls, text: str, source: str | None = None) -> SensorLayout:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise EctskinError(
                f"{source or 'layout'}: not valid JSON (line {exc.lineno}, column {exc.colno}: "
                f"{exc.msg})"
            ) from None
        return _parse_layout(d, source)


def load_layout(path: str | Path) -> SensorLayout:
    """Read and validate a layout JSON file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise EctskinError(f"cannot read layout file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise EctskinError(f"layout file {path} is not UTF-8 text (is it a JSON layout?)") from None
    return SensorLayout.from_json(text, source=str(path))


def default_layout() -> SensorLayout:
    """The paper's layout: two 4-wire skins (front electrodes 1–4, back 5–8), 18 regions, 5 markers.

    Assumed arrangement (DESIGN.md): wires at x = -15, -5, +5, +15 mm, 20/45/70/95 mm long, from
    5 × 5 mm pads near the base; regions a 3 × 3 grid per skin; markers on the right side face.
    """
    text = resources.files("ectskin.layout").joinpath("data/paper_layout.json").read_text()
    return SensorLayout.from_json(text, source="ectskin:paper_layout.json")


# --------------------------------------------------------------------------- parsing
def _get(d: Any, key: str, src: str | None, field_: str):
    if not isinstance(d, dict):
        raise EctskinError(f"{_loc(src, field_)} must be an object, got {type(d).__name__}")
    if key not in d:
        raise EctskinError(f"{_loc(src, field_)}: missing field {key!r}")
    return d[key]


def _loc(src: str | None, field_: str) -> str:
    return f"{src or 'layout'}: {field_}" if field_ else (src or "layout")


def _num_pair(v: Any, src: str | None, field_: str, ordered: bool = False) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in v)
    except (TypeError, ValueError):
        raise EctskinError(f"{_loc(src, field_)} must be two numbers, got {v!r}") from None
    if not (np.isfinite(a) and np.isfinite(b)):
        raise EctskinError(f"{_loc(src, field_)} must be finite, got {v!r}")
    if ordered and not a < b:
        raise EctskinError(f"{_loc(src, field_)} must be [low, high] with low < high, got {v!r}")
    return a, b


def _parse_layout(d: Any, src: str | None) -> SensorLayout:
    if not isinstance(d, dict):
        raise EctskinError(f"{_loc(src, '')}: a layout must be a JSON object")
    schema = d.get("schema")
    if schema != LAYOUT_SCHEMA:
        raise EctskinError(f"{_loc(src, 'schema')}: expected {LAYOUT_SCHEMA!r}, found {schema!r}")
    version = d.get("version")
    if version != LAYOUT_VERSION:
        raise EctskinError(
            f"{_loc(src, 'version')}: this ectskin reads layout version {LAYOUT_VERSION}, "
            f"found {version!r}"
        )
    name = str(_get(d, "name", src, ""))
    if "\x00" in name:
        raise EctskinError(f"{_loc(src, 'name')}: a layout name must not hold a NUL byte")

    skins = []
    for k, s in enumerate(_list(d, "skins", src)):
        f = f"skins[{k}]"
        surface = str(_get(s, "surface", src, f))
        if surface not in SURFACES:
            raise EctskinError(
                f"{_loc(src, f + '.surface')}: expected one of {', '.join(SURFACES)}, "
                f"found {surface!r}"
            )
        skins.append(
            Skin(
                name=str(_get(s, "name", src, f)),
                surface=surface,
                u_mm=_num_pair(_get(s, "u_mm", src, f), src, f + ".u_mm", ordered=True),
                v_mm=_num_pair(_get(s, "v_mm", src, f), src, f + ".v_mm", ordered=True),
            )
        )
    _unique([s.name for s in skins], src, "skins", "skin")
    skin_by_name = {s.name: s for s in skins}

    electrodes = []
    for k, e in enumerate(_list(d, "electrodes", src)):
        f = f"electrodes[{k}]"
        ename = str(_get(e, "name", src, f))
        skin = str(_get(e, "skin", src, f))
        if skin not in skin_by_name:
            raise EctskinError(
                f"{_loc(src, f + '.skin')}: electrode {ename!r} names skin {skin!r}, "
                f"but the layout has {sorted(skin_by_name)}"
            )
        try:
            poly = np.asarray(_get(e, "polyline_mm", src, f), dtype=np.float64)
        except (TypeError, ValueError):
            raise EctskinError(
                f"{_loc(src, f + '.polyline_mm')} must be [[u, v], ...] numbers"
            ) from None
        if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 2:
            raise EctskinError(
                f"{_loc(src, f + '.polyline_mm')}: expected at least 2 points of (u, v), "
                f"got shape {poly.shape}"
            )
        if not np.all(np.isfinite(poly)) or np.any(np.linalg.norm(np.diff(poly, axis=0), axis=1) <= 0):
            raise EctskinError(
                f"{_loc(src, f + '.polyline_mm')}: points must be finite and distinct in sequence"
            )
        width = float(_get(e, "width_mm", src, f))
        if not (0 < width < 50):
            raise EctskinError(f"{_loc(src, f + '.width_mm')}: expected 0 < width < 50 mm, got {width}")
        pad = _get(e, "pad", src, f)
        pc = _num_pair(_get(pad, "centre_mm", src, f + ".pad"), src, f + ".pad.centre_mm")
        ps = _num_pair(_get(pad, "size_mm", src, f + ".pad"), src, f + ".pad.size_mm")
        if min(ps) <= 0:
            raise EctskinError(f"{_loc(src, f + '.pad.size_mm')}: sizes must be > 0, got {ps}")
        el = Electrode(ename, skin, poly, width, pc, ps)
        outside = ~skin_by_name[skin].contains(el.outline_points())
        if outside.any():
            pt = el.outline_points()[np.argmax(outside)]
            sk = skin_by_name[skin]
            raise EctskinError(
                f"{_loc(src, f)}: electrode {ename!r} is off its skin {skin!r}: point "
                f"({pt[0]:.2f}, {pt[1]:.2f}) mm lies outside u {list(sk.u_mm)}, v {list(sk.v_mm)}"
            )
        electrodes.append(el)
    if len(electrodes) < 2:
        raise EctskinError(f"{_loc(src, 'electrodes')}: need at least 2 electrodes, got {len(electrodes)}")
    _unique([e.name for e in electrodes], src, "electrodes", "electrode")
    _check_overlaps(electrodes, skin_by_name, src)

    regions = []
    for k, r in enumerate(d.get("regions", [])):
        f = f"regions[{k}]"
        rid = _get(r, "id", src, f)
        if not isinstance(rid, int) or isinstance(rid, bool) or rid < 1:
            raise EctskinError(f"{_loc(src, f + '.id')}: expected an integer >= 1, got {rid!r}")
        surface = str(_get(r, "surface", src, f))
        if surface not in SURFACES:
            raise EctskinError(
                f"{_loc(src, f + '.surface')}: expected one of {', '.join(SURFACES)}, found {surface!r}"
            )
        regions.append(
            Region(
                rid,
                surface,
                _num_pair(_get(r, "u_mm", src, f), src, f + ".u_mm", ordered=True),
                _num_pair(_get(r, "v_mm", src, f), src, f + ".v_mm", ordered=True),
            )
        )
    _unique([r.id for r in regions], src, "regions", "region id")
    if regions and sorted(r.id for r in regions) != list(range(1, len(regions) + 1)):
        raise EctskinError(
            f"{_loc(src, 'regions')}: region ids must be 1..{len(regions)} (class 0 is 'no touch'), "
            f"got {sorted(r.id for r in regions)}"
        )

    markers = []
    for k, m in enumerate(d.get("markers", [])):
        f = f"markers[{k}]"
        surface = str(_get(m, "surface", src, f))
        if surface not in SURFACES:
            raise EctskinError(
                f"{_loc(src, f + '.surface')}: expected one of {', '.join(SURFACES)}, found {surface!r}"
            )
        markers.append(
            Marker(
                str(_get(m, "name", src, f)),
                surface,
                _num_pair(_get(m, "uv_mm", src, f), src, f + ".uv_mm"),
            )
        )
    _unique([m.name for m in markers], src, "markers", "marker")
    return SensorLayout(name, tuple(skins), tuple(electrodes), tuple(regions), tuple(markers), src)


def _list(d: dict, key: str, src: str | None) -> list:
    v = _get(d, key, src, "")
    if not isinstance(v, list):
        raise EctskinError(f"{_loc(src, key)} must be a list, got {type(v).__name__}")
    return v


def _unique(names: list, src: str | None, field_: str, what: str) -> None:
    """Names are unique and storable: a string name is non-empty and holds no NUL byte."""
    seen = set()
    for n in names:
        if isinstance(n, str) and (not n.strip() or "\x00" in n):
            raise EctskinError(
                f"{_loc(src, field_)}: {what} name {n!r} must be non-empty text without NUL bytes"
            )
        if n in seen:
            raise EctskinError(f"{_loc(src, field_)}: duplicate {what} {n!r}")
        seen.add(n)


def _check_overlaps(electrodes: list[Electrode], skins: dict[str, Skin], src: str | None) -> None:
    """Refuse two electrodes whose wires or pads touch or cross on the same surface.

    Each wire is sampled along its centre line and compared with the other's segments: the
    distance between centre lines must exceed half the sum of the widths (pads as rectangles).
    """
    shapes = []
    for e in electrodes:
        surface = skins[e.skin].surface
        shapes.append((surface, sample_polyline(e.polyline_mm, step_mm=0.25), e))
    for a in range(len(shapes)):
        for b in range(a + 1, len(shapes)):
            sa, pa, ea = shapes[a]
            sb, _, eb = shapes[b]
            if sa != sb:
                continue
            gap = polyline_distance(pa, eb.polyline_mm) - (ea.width_mm + eb.width_mm) / 2
            pad_hit = pad_touches(ea, eb) or pad_touches(eb, ea)
            if gap <= 0 or pad_hit:
                raise EctskinError(
                    f"{_loc(src, 'electrodes')}: electrodes {ea.name!r} and {eb.name!r} overlap on "
                    f"surface {sa!r} (wires or pads touch); they would short together"
                )
