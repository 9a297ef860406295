"""What a response field is computed from (:class:`FieldSpec`), its grid, and its cache key.

A response field (:mod:`ectskin.twin.field`) holds the readouts of one sensor state for a
grounded finger at the nodes of a grid: per face, rest surface coordinates (u, v) on a regular
grid over the face's skin, and per (u, v) either the finger pressing with a force F (contact,
Chebyshev nodes in F) or hovering at a height h (force 0, Chebyshev nodes in ln h).

The cache key (:meth:`FieldSpec.key`) is the SHA-256 of the canonical JSON of everything the
node values depend on:

* the spec itself: layout, manipulator, discretisation, permittivities, finger, inflation state,
  faces and window, grid spacing, force and height nodes;
* the physics code: ``ectskin.__version__`` and a digest of the source text of every ectskin
  module the node solves import, transitively (:func:`physics_digest`: the sensor, mechanics,
  rod, electrostatics and layout modules, and the field's own solver). An edit of any of them,
  even one made without a version bump (an uncommitted change of the contact law), gives a
  new key, so a stale field is never read back;
* :data:`FIELD_FORMAT`, the layout of the files.

The interpolation (:mod:`ectskin.twin.field`) is rebuilt from the node values at load, so it is
not part of the key.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

import ectskin
from ectskin._check import EctskinError
from ectskin.layout import SensorLayout
from ectskin.twin.mechanics import Manipulator, ManipulatorConfig
from ectskin.twin.response import chebyshev_nodes
from ectskin.twin.sensor import Discretisation, Finger, SensorModel

#: version of the cache's file layout (manifest, chunks, field.npz)
FIELD_FORMAT = 1
#: a mesh for quick fields (tests, the benchmark's default): 4 mm wire panels, a coarse fingertip
#: and cavity grid; its interpolation against direct solves is measured by benchmarks/bench_field.py
COARSE_FIELD_MESH = Discretisation(
    wire_panel_length_mm=4.0,
    wire_panels_across=1,
    pad_panels=2,
    finger_sphere_n=3,
    finger_shaft_around=8,
    finger_shaft_along=3,
    cavity_cell_mm=8.0,
    cavity_layers=2,
)
#: the modules whose import closure is the physics of the node values (:func:`physics_digest`):
#: the chunk solver, which imports this module (the nodes), the sensor and the electrostatics
PHYSICS_ROOTS = ("ectskin.twin.field_solve",)
#: ectskin modules that never change a computed number (checks, file writing): left out of the
#: digest so that editing a message does not invalidate every cached field
NOT_PHYSICS = ("ectskin", "ectskin._check", "ectskin._files")


@dataclass(frozen=True)
class FieldSpec:
    """Everything a response field is computed from; :meth:`key` is its cache key.

    Parameters
    ----------
    layout : the e-skin layout; the grid covers each face's skin (``layout.skins``).
    inflation_ml : the state, one volume per chamber (ml).
    manipulator, discretisation, eps_r, chamber_eps_r, finger : as :class:`SensorModel`.
    spacing_mm : (du, dv), the largest grid step along u and v (mm); each face's extent is cut
        into equal steps no longer than these.
    force_range_n, force_nodes : contact forces, Chebyshev nodes on the range (N). The field
        interpolates in force by the polynomial through them, as the twin's trial models do.
    height_range_mm, height_nodes : hover heights (force 0), Chebyshev nodes in ln h on the
        range (mm); ``height_nodes=0``: no hover part.
    faces : the surfaces to cover (default: every skin's surface).
    window_mm : optional ((u_lo, u_hi), (v_lo, v_hi)) that limits every face's grid to a window
        inside its skin (a study of one area, a small test field).
    fine_spacing_mm, refine_u_mm, refine_v_mm : a graded grid: inside the intervals
        ``refine_u_mm`` of u (and ``refine_v_mm`` of v), ((lo, hi), ...) mm, the grid has nodes
        every ``fine_spacing_mm`` = (du, dv) too (where the readout has kinks: beside the
        bulges' edges, :func:`chamber_refinement`). Default: none, the grid is uniform.
    """

    layout: SensorLayout
    inflation_ml: tuple[float, ...]
    manipulator: ManipulatorConfig = field(default_factory=ManipulatorConfig)
    discretisation: Discretisation = field(default_factory=Discretisation)
    eps_r: float = 2.0
    chamber_eps_r: float | None = 1.0
    finger: Finger = field(default_factory=Finger)
    spacing_mm: tuple[float, float] = (2.0, 2.0)
    force_range_n: tuple[float, float] = (0.3, 2.0)
    force_nodes: int = 6
    height_range_mm: tuple[float, float] = (0.5, 15.0)
    height_nodes: int = 6
    faces: tuple[str, ...] | None = None
    window_mm: tuple[tuple[float, float], tuple[float, float]] | None = None
    fine_spacing_mm: tuple[float, float] | None = None
    refine_u_mm: tuple[tuple[float, float], ...] = ()
    refine_v_mm: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.layout, SensorLayout):
            raise EctskinError(
                f"FieldSpec.layout must be a SensorLayout, got {type(self.layout).__name__}"
            )
        for name, typ in (
            ("manipulator", ManipulatorConfig),
            ("discretisation", Discretisation),
            ("finger", Finger),
        ):
            if not isinstance(getattr(self, name), typ):
                raise EctskinError(
                    f"FieldSpec.{name} must be a {typ.__name__}, got "
                    f"{type(getattr(self, name)).__name__}"
                )
        infl = Manipulator(self.manipulator).check_inflation(self.inflation_ml)
        object.__setattr__(self, "inflation_ml", tuple(float(x) for x in infl))
        spacing = _floats("spacing_mm", self.spacing_mm, 2)
        if not all(s > 0 for s in spacing):
            raise EctskinError(f"FieldSpec.spacing_mm must be two steps > 0 mm, got {spacing}")
        object.__setattr__(self, "spacing_mm", spacing)
        if self.fine_spacing_mm is not None:
            fine = _floats("fine_spacing_mm", self.fine_spacing_mm, 2)
            if not all(0 < f <= s for f, s in zip(fine, spacing)):
                raise EctskinError(
                    f"FieldSpec.fine_spacing_mm must be two steps > 0 and <= spacing_mm {spacing}, "
                    f"got {fine}"
                )
            object.__setattr__(self, "fine_spacing_mm", fine)
        for name in ("refine_u_mm", "refine_v_mm"):
            bands = _intervals(name, getattr(self, name))
            if bands and self.fine_spacing_mm is None:
                raise EctskinError(f"FieldSpec.{name} needs fine_spacing_mm (the steps inside)")
            object.__setattr__(self, name, bands)
        lo, hi = _floats("force_range_n", self.force_range_n, 2)
        if not 0 < lo < hi:
            raise EctskinError(f"FieldSpec.force_range_n must be 0 < low < high (N), got {(lo, hi)}")
        object.__setattr__(self, "force_range_n", (lo, hi))
        _count("force_nodes", self.force_nodes, 2)
        lo, hi = _floats("height_range_mm", self.height_range_mm, 2)
        if not 0 < lo < hi:
            raise EctskinError(
                f"FieldSpec.height_range_mm must be 0 < low < high (mm), got {(lo, hi)}"
            )
        object.__setattr__(self, "height_range_mm", (lo, hi))
        if self.height_nodes != 0:
            _count("height_nodes", self.height_nodes, 2)
        for name in ("eps_r",) + (() if self.chamber_eps_r is None else ("chamber_eps_r",)):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 1.0):
                raise EctskinError(f"FieldSpec.{name} must be a relative permittivity >= 1, got {v!r}")
        surfaces = tuple(s.surface for s in self.layout.skins)
        faces = surfaces if self.faces is None else tuple(self.faces)
        for f in faces:
            if f not in surfaces:
                raise EctskinError(
                    f"FieldSpec.faces: {f!r} is not a skin's surface in layout "
                    f"{self.layout.name!r}; expected some of {list(surfaces)}"
                )
        if len(set(faces)) != len(faces) or not faces:
            raise EctskinError(f"FieldSpec.faces must name distinct surfaces, got {list(faces)}")
        object.__setattr__(self, "faces", faces)
        if self.window_mm is not None:
            try:
                (ulo, uhi), (vlo, vhi) = self.window_mm
                window = ((float(ulo), float(uhi)), (float(vlo), float(vhi)))
            except (TypeError, ValueError):
                raise EctskinError(
                    f"FieldSpec.window_mm must be ((u_lo, u_hi), (v_lo, v_hi)) mm, got "
                    f"{self.window_mm!r}"
                ) from None
            object.__setattr__(self, "window_mm", window)
        for f in faces:
            (ulo, uhi), (vlo, vhi) = self.extent(f)
            if not (ulo < uhi and vlo < vhi):
                raise EctskinError(
                    f"FieldSpec.window_mm {self.window_mm} leaves nothing of face {f!r}'s skin "
                    f"({self._skin(f).u_mm}, {self._skin(f).v_mm})"
                )

    # ------------------------------------------------------------------ grid
    def _skin(self, face: str):
        for s in self.layout.skins:
            if s.surface == face:
                return s
        raise EctskinError(f"no skin on face {face!r} (faces: {list(self.faces or ())})")

    def extent(self, face: str) -> tuple[tuple[float, float], tuple[float, float]]:
        """((u_lo, u_hi), (v_lo, v_hi)) mm that the grid of ``face`` covers."""
        s = self._skin(face)
        (ulo, uhi), (vlo, vhi) = s.u_mm, s.v_mm
        if self.window_mm is not None:
            (wul, wuh), (wvl, wvh) = self.window_mm
            ulo, uhi, vlo, vhi = max(ulo, wul), min(uhi, wuh), max(vlo, wvl), min(vhi, wvh)
        return (float(ulo), float(uhi)), (float(vlo), float(vhi))

    def grid(self, face: str) -> tuple[np.ndarray, np.ndarray]:
        """(u nodes (n_u,), v nodes (n_v,)) mm of ``face``, ascending: equal steps of at most
        ``spacing_mm`` over :meth:`extent`, the ends included; inside each refinement interval
        those nodes give way to nodes every ``fine_spacing_mm`` from the interval's start (less
        any within half a fine step of a node kept)."""
        out = []
        fine = self.fine_spacing_mm or (0.0, 0.0)
        for (lo, hi), step, f, bands in zip(
            self.extent(face), self.spacing_mm, fine, (self.refine_u_mm, self.refine_v_mm)
        ):
            n = max(2, int(math.ceil((hi - lo) / step - 1e-9)) + 1)
            nodes = np.linspace(lo, hi, n)
            for a, b in bands:
                a, b = max(a, lo), min(b, hi)
                if a >= b:
                    continue
                nodes = nodes[(nodes <= a) | (nodes >= b)]  # inside, the fine steps instead
                for x in a + f * np.arange(int(math.floor((b - a) / f + 1e-9)) + 1):
                    if np.min(np.abs(nodes - x)) >= 0.5 * f:
                        nodes = np.sort(np.append(nodes, x))
            out.append(nodes)
        return out[0], out[1]

    def forces(self) -> np.ndarray:
        """(force_nodes,) contact forces (N), Chebyshev nodes on ``force_range_n``, ascending."""
        return np.sort(chebyshev_nodes(*self.force_range_n, self.force_nodes))

    def heights(self) -> np.ndarray:
        """(height_nodes,) hover heights (mm), Chebyshev nodes in ln h, ascending (may be empty)."""
        if self.height_nodes == 0:
            return np.zeros(0)
        lo, hi = np.log(self.height_range_mm)
        return np.sort(np.exp(chebyshev_nodes(lo, hi, self.height_nodes)))

    @property
    def face_names(self) -> tuple[str, ...]:
        """The faces the field covers (``faces``, filled in from the layout)."""
        return tuple(self.faces or ())

    @property
    def n_pairs(self) -> int:
        return self.layout.n_pairs

    def sensor(self) -> SensorModel:
        """The :class:`SensorModel` that solves this spec's nodes."""
        return SensorModel(
            self.layout,
            Manipulator(self.manipulator),
            self.discretisation,
            eps_r=self.eps_r,
            finger=self.finger,
            chamber_eps_r=self.chamber_eps_r,
        )

    # ------------------------------------------------------------------ (de)serialise, key
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (non-finite floats as the strings "inf", "-inf")."""
        return _canon(
            {
                "layout": self.layout.to_dict(),
                "inflation_ml": self.inflation_ml,
                "manipulator": asdict(self.manipulator),
                "discretisation": asdict(self.discretisation),
                "eps_r": self.eps_r,
                "chamber_eps_r": self.chamber_eps_r,
                "finger": asdict(self.finger),
                "spacing_mm": self.spacing_mm,
                "force_range_n": self.force_range_n,
                "force_nodes": self.force_nodes,
                "height_range_mm": self.height_range_mm,
                "height_nodes": self.height_nodes,
                "faces": self.faces,
                "window_mm": self.window_mm,
                **(
                    {}
                    if self.fine_spacing_mm is None
                    else {
                        "fine_spacing_mm": self.fine_spacing_mm,
                        "refine_u_mm": self.refine_u_mm,
                        "refine_v_mm": self.refine_v_mm,
                    }
                ),
            }
        )

    @classmethod
    def from_dict(cls, d: Any, source: str = "field spec") -> FieldSpec:
        """The spec back from :meth:`to_dict` (a field file's or a manifest's)."""
        if not isinstance(d, dict):
            raise EctskinError(f"{source}: expected a JSON object, got {type(d).__name__}")
        try:
            kw = dict(d)
            kw["layout"] = SensorLayout.from_dict(kw["layout"], source=f"{source}: layout")
            for name, typ in (
                ("manipulator", ManipulatorConfig),
                ("discretisation", Discretisation),
                ("finger", Finger),
            ):
                names = {f.name for f in fields(typ)}
                given = _uncanon(kw[name])
                unknown = sorted(set(given) - names)
                if unknown:
                    raise EctskinError(
                        f"{source}: {name} has unknown field(s) {unknown}; the field was written by "
                        f"another version of ectskin"
                    )
                kw[name] = typ(**given)
            for name in ("inflation_ml", "spacing_mm", "force_range_n", "height_range_mm", "faces"):
                kw[name] = _uncanon(kw[name])
            for name in ("window_mm", "fine_spacing_mm", "refine_u_mm", "refine_v_mm"):
                if kw.get(name) is not None:
                    kw[name] = _uncanon(kw[name])
            return cls(**kw)
        except (KeyError, TypeError) as exc:
            raise EctskinError(f"{source}: not a field spec ({type(exc).__name__}: {exc})") from None

    def canonical_json(self) -> str:
        """The canonical JSON the key hashes: the spec, the physics digest and the format."""
        doc = {
            "format": FIELD_FORMAT,
            "ectskin": ectskin.__version__,
            "physics": physics_digest(),
            "spec": self.to_dict(),
        }
        return json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)

    def key(self) -> str:
        """The cache key: SHA-256 (hex) of :meth:`canonical_json`."""
        return hashlib.sha256(self.canonical_json().encode("utf-8")).hexdigest()


# ---------------------------------------------------------------------- the demo's grid
@dataclass(frozen=True)
class FieldGrid:
    """How finely a field samples its state: the grid steps (u, v) mm, the force and height
    nodes, the mesh of the node solves (:class:`FieldSpec`'s fields of the same names), and
    optionally a graded grid: steps ``fine_spacing_mm`` within ``wall_band_mm`` of the chambers'
    side walls (in u) and within ``end_band_mm`` of their ends (in v), where the bulges' edges
    put kinks into the readout (:func:`chamber_refinement`)."""

    spacing_mm: tuple[float, float]
    force_nodes: int
    height_nodes: int
    discretisation: Discretisation = COARSE_FIELD_MESH
    fine_spacing_mm: tuple[float, float] | None = None
    wall_band_mm: float = 5.0
    end_band_mm: float = 3.0


#: the grid that meets the field's accuracy bar (0.5 fF and 2 % of the finger's signal) on
#: nearly every point, chosen by the interpolation error against direct solves
#: (``benchmarks/bench_field_grid.py``): 2 mm across the wires (u) and 4 mm along them, 1 mm
#: near the chambers' side walls and ends (the errors of a uniform grid gather there: the
#: fingertip rests against a bulge's shoulder), Chebyshev nodes: 6 in force, 6 in ln h (4
#: height nodes missed the bound on half the hover points)
FINE_FIELD = FieldGrid(
    spacing_mm=(2.0, 4.0), force_nodes=6, height_nodes=6, fine_spacing_mm=(1.0, 1.0)
)
#: the reproduction's contact fields (``ReproduceConfig.field_grid="quick"``, the default): the
#: same steps without the graded bands and 4 force nodes, about a quarter of
#: :data:`FINE_FIELD`'s solves, so that the demo's 8 states build in minutes on 2 cores; its
#: contact nodes miss the bar near the chambers' walls and ends (about 80 % of whole-face
#: points within it at 6 force nodes, max 2.2 fF; docs/field.md), an error of the training
#: data of the order of the coarse mesh's own (1-2 % of the finger's signal)
QUICK_FIELD = FieldGrid(spacing_mm=(2.0, 4.0), force_nodes=4, height_nodes=6)
#: the grids by name (``ReproduceConfig.field_grid``, ``ectskin simulate --field-grid``)
FIELD_GRIDS = {"quick": QUICK_FIELD, "fine": FINE_FIELD}


def chamber_refinement(
    manipulator: ManipulatorConfig, wall_band_mm: float, end_band_mm: float, merge_mm: float
) -> tuple[tuple[tuple[float, float], ...], tuple[tuple[float, float], ...]]:
    """(u intervals, v intervals) mm of a graded grid: within ``wall_band_mm`` of the chambers'
    side walls (u = ±chamber_size_x / 2) and within ``end_band_mm`` of every chamber end along
    v; v intervals less than ``merge_mm`` apart are joined (the gap between two chambers)."""
    c = manipulator
    half = c.chamber_size_x_mm / 2
    w = float(wall_band_mm)
    u = ((-half - w, -half + w), (half - w, half + w))
    ends = sorted(
        z + s * c.chamber_size_z_mm / 2 for z in c.chamber_centres_z_mm for s in (-1.0, 1.0)
    )
    v: list[tuple[float, float]] = []
    for z in ends:
        lo, hi = z - end_band_mm, z + end_band_mm
        if v and lo - v[-1][1] <= merge_mm:
            v[-1] = (v[-1][0], hi)
        else:
            v.append((lo, hi))
    return u, tuple(v)


def contact_field_spec(
    layout: SensorLayout, inflation_ml, grid: FieldGrid = FINE_FIELD, **kw: Any
) -> FieldSpec:
    """The :class:`FieldSpec` of one state of the contact experiment on ``grid`` (default
    :data:`FINE_FIELD`); ``kw``: any other :class:`FieldSpec` field (finger, force_range_n,
    height_range_mm, manipulator, faces, window_mm, ...)."""
    if not isinstance(grid, FieldGrid):
        raise EctskinError(f"contact_field_spec: grid must be a FieldGrid, got {type(grid).__name__}")
    taken = {"spacing_mm", "force_nodes", "height_nodes", "discretisation", "fine_spacing_mm",
             "refine_u_mm", "refine_v_mm"}
    clash = sorted(taken & set(kw))
    if clash:
        raise EctskinError(f"contact_field_spec: {clash} come from grid; give a FieldGrid instead")
    refine: dict[str, Any] = {}
    if grid.fine_spacing_mm is not None:
        u, v = chamber_refinement(
            kw.get("manipulator", ManipulatorConfig()), grid.wall_band_mm, grid.end_band_mm,
            grid.spacing_mm[1],
        )
        refine = {"fine_spacing_mm": grid.fine_spacing_mm, "refine_u_mm": u, "refine_v_mm": v}
    return FieldSpec(
        layout, inflation_ml, discretisation=grid.discretisation, spacing_mm=grid.spacing_mm,
        force_nodes=grid.force_nodes, height_nodes=grid.height_nodes, **refine, **kw,
    )


# ---------------------------------------------------------------------- the physics digest
def _module_file(root: Path, name: str) -> Path | None:
    """The source file of ectskin module ``name`` under the package folder ``root``."""
    parts = name.split(".")[1:]
    if not parts:
        return root / "__init__.py"
    rel = Path(*parts)
    for cand in (root / rel / "__init__.py", root / rel.with_suffix(".py")):
        if cand.is_file():
            return cand
    return None


def _ectskin_imports(path: Path, name: str, root: Path) -> set[str]:
    """The ectskin modules ``path`` (module ``name``) imports, at any depth of the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "ectskin"}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - (node.level - 1)] + ([base] if base else []))
            if base.split(".")[0] != "ectskin":
                continue
            found.add(base)
            found |= {
                f"{base}.{a.name}" for a in node.names if _module_file(root, f"{base}.{a.name}")
            }
    return {m for m in found if _module_file(root, m) is not None}


def physics_modules() -> list[str]:
    """The ectskin modules in the import closure of :data:`PHYSICS_ROOTS`, less
    :data:`NOT_PHYSICS`, sorted: the code of the physics."""
    root = Path(ectskin.__file__).resolve().parent
    todo, seen = list(PHYSICS_ROOTS), set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        path = _module_file(root, name)
        if path is not None:
            todo.extend(_ectskin_imports(path, name, root) - seen)
    return sorted(seen - set(NOT_PHYSICS))


@functools.lru_cache(maxsize=1)
def physics_digest() -> str:
    """SHA-256 (hex) of the source text of :func:`physics_modules`, by module name (computed
    once per process)."""
    root = Path(ectskin.__file__).resolve().parent
    h = hashlib.sha256()
    for name in physics_modules():
        path = _module_file(root, name)
        if path is not None:
            h.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


# ---------------------------------------------------------------------- small helpers
def _canon(obj: Any) -> Any:
    """Plain JSON values; non-finite floats become "inf" / "-inf" / "nan" (strings)."""
    if isinstance(obj, dict):
        return {str(k): _canon(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_canon(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _canon(obj.tolist())
    if isinstance(obj, np.generic):
        return _canon(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


def _uncanon(obj: Any) -> Any:
    """:func:`_canon` undone for a dataclass's fields: lists become tuples, "inf" a float."""
    if isinstance(obj, dict):
        return {k: _uncanon(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return tuple(_uncanon(v) for v in obj)
    if isinstance(obj, str) and obj in ("inf", "-inf", "nan"):
        return float(obj)
    return obj


def _floats(name: str, value: Any, n: int) -> tuple[float, ...]:
    try:
        out = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise EctskinError(f"FieldSpec.{name} must be {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(x) for x in out):
        raise EctskinError(f"FieldSpec.{name} must be {n} finite numbers, got {value!r}")
    return out


def _intervals(name: str, value: Any) -> tuple[tuple[float, float], ...]:
    try:
        out = tuple((float(a), float(b)) for a, b in value)
    except (TypeError, ValueError):
        raise EctskinError(f"FieldSpec.{name} must be ((lo, hi), ...) mm, got {value!r}") from None
    if not all(math.isfinite(a) and math.isfinite(b) and a < b for a, b in out):
        raise EctskinError(f"FieldSpec.{name} must be finite intervals lo < hi (mm), got {out}")
    return out


def _count(name: str, value: Any, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
        raise EctskinError(f"FieldSpec.{name} must be an integer >= {least}, got {value!r}")
    return int(value)
