"""The response field: the readouts of one sensor state for a finger anywhere on the faces.

DESIGN.md, "The physical limit and the response field": build once, solve many. A
:class:`ResponseField` holds the method-of-moments readouts (n_pairs, pF) of one inflation state
at the nodes of a grid (:class:`~ectskin.twin.field_spec.FieldSpec`), per face:

* contact: rest surface coordinates (u, v) × forces F (the finger pressing), values
  ``(n_u, n_v, n_forces, n_pairs)``;
* hover: (u, v) × heights h (force 0), values ``(n_u, n_v, n_heights, n_pairs)``;

and the untouched readout of the state, so Δc = c − c_untouched is at hand.

Between the nodes it interpolates by tensor-product B-splines (scipy ``NdBSpline``): cubic
not-a-knot splines in u and in v, and in F the polynomial through the Chebyshev force nodes
(in ln h through the height nodes), as the twin's trial models interpolate in force
(:mod:`ectskin.twin.response`). The interpolant is C² in (u, v) and smooth in F and h, so
:meth:`ResponseField.jacobian` gives ∂C/∂(u, v, F, h) from the same splines.

The field is exact at its nodes; between them its error against direct solves is measured by
``tests/twin/test_field.py`` and ``benchmarks/bench_field.py`` (``docs/field.md``).
Building and caching: :mod:`ectskin.twin.field_build`.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import NdBSpline, make_interp_spline

from ectskin._check import EctskinError
from ectskin._files import atomic_write
from ectskin.twin.field_spec import FIELD_FORMAT, FieldSpec

#: the columns of :meth:`ResponseField.jacobian`
JACOBIAN_AXES = ("u_mm", "v_mm", "force_n", "height_mm")
#: how far (mm, N) a query may lie outside the grid and still count as on it (round-off)
_EDGE_TOL = 1e-9


def _spline(axes: list[tuple[np.ndarray, int, np.ndarray | None]], values: np.ndarray) -> NdBSpline:
    """The tensor-product interpolating B-spline of ``values`` (n_0, ..., n_d−1, n_pairs) over
    ``axes`` [(nodes, degree, knots or None for not-a-knot)], one axis at a time."""
    c = values
    ts, ks = [], []
    for ax, (x, k, t) in enumerate(axes):
        s = make_interp_spline(x, c, k=k, t=t, axis=ax)
        c = np.moveaxis(s.c, 0, ax)
        ts.append(s.t)
        ks.append(k)
    return NdBSpline(tuple(ts), c, tuple(ks), extrapolate=True)


def _clamped(lo: float, hi: float, k: int) -> np.ndarray:
    """Knots of one polynomial piece of degree k on [lo, hi] (the Bernstein basis)."""
    return np.r_[[lo] * (k + 1), [hi] * (k + 1)]


class ResponseField:
    """Readouts of one sensor state for a finger at any point, force and height (module doc).

    Parameters
    ----------
    spec : what the field was computed from (grid, forces, heights, physics).
    untouched : (n_pairs,) pF, the state without a finger.
    contact : face → (n_u, n_v, n_forces, n_pairs) pF at the nodes of ``spec``.
    hover : face → (n_u, n_v, n_heights, n_pairs) pF (empty dict if ``spec.height_nodes == 0``).
    key : the cache key the values were computed under (default ``spec.key()``).
    """

    def __init__(
        self,
        spec: FieldSpec,
        untouched,
        contact: dict[str, np.ndarray],
        hover: dict[str, np.ndarray],
        key: str | None = None,
    ) -> None:
        if not isinstance(spec, FieldSpec):
            raise EctskinError(f"ResponseField: spec must be a FieldSpec, got {type(spec).__name__}")
        self.spec = spec
        self.key = spec.key() if key is None else str(key)
        p = spec.n_pairs
        self.untouched = _values("untouched", untouched, (p,))
        self.forces_n = spec.forces()
        self.heights_mm = spec.heights()
        self._contact: dict[str, np.ndarray] = {}
        self._hover: dict[str, np.ndarray] = {}
        for face in spec.face_names:
            u, v = spec.grid(face)
            self._contact[face] = _values(
                f"contact[{face!r}]", contact.get(face), (u.size, v.size, self.forces_n.size, p)
            )
            if self.heights_mm.size:
                self._hover[face] = _values(
                    f"hover[{face!r}]", hover.get(face), (u.size, v.size, self.heights_mm.size, p)
                )
        self._splines: dict[tuple[str, str], NdBSpline] = {}

    def __repr__(self) -> str:
        return (
            f"ResponseField(faces={list(self.faces)}, inflation_ml={list(self.spec.inflation_ml)}, "
            f"n_pairs={self.n_pairs}, key={self.key[:12]})"
        )

    # ------------------------------------------------------------------ shape
    @property
    def faces(self) -> tuple[str, ...]:
        return self.spec.face_names

    @property
    def n_pairs(self) -> int:
        return self.spec.n_pairs

    def grid(self, face: str) -> tuple[np.ndarray, np.ndarray]:
        """(u nodes, v nodes) mm of ``face``."""
        return self.spec.grid(self._face(face))

    def node_values(self, face: str, part: str = "contact") -> np.ndarray:
        """The node readouts of ``face`` (a read-only view): ``part`` "contact" (n_u, n_v,
        n_forces, n_pairs) or "hover" (n_u, n_v, n_heights, n_pairs), pF."""
        face = self._face(face)
        table = {"contact": self._contact, "hover": self._hover}
        if part not in table or face not in table[part]:
            raise EctskinError(f"node_values: part must be 'contact' or 'hover' (with heights), got {part!r}")
        out = table[part][face].view()
        out.setflags(write=False)
        return out

    # ------------------------------------------------------------------ queries
    def readout(self, face: str, u_mm, v_mm, force_n, height_mm=0.0) -> np.ndarray:
        """(..., n_pairs) pF, interpolated: the finger at (u, v) on ``face``.

        ``u_mm, v_mm, force_n, height_mm`` broadcast to one shape (...). Where ``height_mm`` is
        0 the finger presses with ``force_n`` (within ``spec.force_range_n``); where it is > 0
        it hovers that high (within ``spec.height_range_mm``) and ``force_n`` must be 0.
        """
        face, q, contact = self._query(face, u_mm, v_mm, force_n, height_mm)
        out = np.empty(q.shape[:-1] + (self.n_pairs,))
        if contact.any():
            out[contact] = self._spline(face, "contact")(q[contact][:, :3])
        if (~contact).any():
            hov = q[~contact]
            out[~contact] = self._spline(face, "hover")(np.c_[hov[:, :2], np.log(hov[:, 3])])
        return out

    def delta(self, face: str, u_mm, v_mm, force_n, height_mm=0.0) -> np.ndarray:
        """(..., n_pairs) pF: :meth:`readout` less the untouched readout (the finger's signal)."""
        return self.readout(face, u_mm, v_mm, force_n, height_mm) - self.untouched

    def jacobian(self, face: str, u_mm, v_mm, force_n, height_mm=0.0) -> np.ndarray:
        """(..., n_pairs, 4) derivatives of :meth:`readout` along :data:`JACOBIAN_AXES`:
        pF/mm in u and v, pF/N in force, pF/mm in height.

        In contact the height column is NaN (the finger is on the skin, its height is not a
        free parameter there); hovering, the force column is NaN (its force is 0).
        """
        face, q, contact = self._query(face, u_mm, v_mm, force_n, height_mm)
        out = np.full(q.shape[:-1] + (self.n_pairs, 4), np.nan)
        if contact.any():
            spl = self._spline(face, "contact")
            x = q[contact][:, :3]
            out[contact, :, 0] = spl(x, nu=(1, 0, 0))
            out[contact, :, 1] = spl(x, nu=(0, 1, 0))
            out[contact, :, 2] = spl(x, nu=(0, 0, 1))
        if (~contact).any():
            spl = self._spline(face, "hover")
            hov = q[~contact]
            x = np.c_[hov[:, :2], np.log(hov[:, 3])]
            out[~contact, :, 0] = spl(x, nu=(1, 0, 0))
            out[~contact, :, 1] = spl(x, nu=(0, 1, 0))
            out[~contact, :, 3] = spl(x, nu=(0, 0, 1)) / hov[:, 3:4]  # d/dh = (d/d ln h) / h
        return out

    # ------------------------------------------------------------------ internals
    def _face(self, face: str) -> str:
        if face not in self.faces:
            raise EctskinError(
                f"response field: unknown face {face!r}; this field covers {list(self.faces)}"
            )
        return face

    def _query(self, face, u_mm, v_mm, force_n, height_mm) -> tuple[str, np.ndarray, np.ndarray]:
        """The face, the queries stacked (..., 4) as (u, v, F, h), and where they are in contact."""
        face = self._face(face)
        try:
            arrays = np.broadcast_arrays(
                *(np.asarray(a, dtype=np.float64) for a in (u_mm, v_mm, force_n, height_mm))
            )
        except ValueError:
            raise EctskinError(
                "response field: u_mm, v_mm, force_n and height_mm must broadcast to one shape, "
                f"got {[np.shape(a) for a in (u_mm, v_mm, force_n, height_mm)]}"
            ) from None
        q = np.stack(arrays, axis=-1)
        if not np.all(np.isfinite(q)):
            raise EctskinError("response field: the query holds NaN or inf")
        (ulo, uhi), (vlo, vhi) = self.spec.extent(face)
        _within("u_mm", q[..., 0], ulo, uhi, f"face {face!r}")
        _within("v_mm", q[..., 1], vlo, vhi, f"face {face!r}")
        h = q[..., 3]
        if np.any(h < 0):
            raise EctskinError(f"response field: height_mm must be >= 0, got {h.min():.4g}")
        contact = h == 0
        fl, fh = self.spec.force_range_n
        _within("force_n", q[..., 2][contact], fl, fh, "contact (height 0)")
        if (~contact).any():
            if not self.heights_mm.size:
                raise EctskinError(
                    "response field: this field has no hover part (height_nodes=0); height_mm "
                    "must be 0"
                )
            if np.any(q[..., 2][~contact] != 0):
                raise EctskinError(
                    "response field: a hovering finger (height_mm > 0) has force_n 0, got "
                    f"{np.abs(q[..., 2][~contact]).max():.4g} N"
                )
            hl, hh = self.spec.height_range_mm
            _within("height_mm", h[~contact], hl, hh, "hover")
        return face, q, contact

    def _spline(self, face: str, part: str) -> NdBSpline:
        key = (face, part)
        if key not in self._splines:
            u, v = self.spec.grid(face)
            if part == "contact":
                x, values, lo, hi = self.forces_n, self._contact[face], *self.spec.force_range_n
            else:
                x, values = np.log(self.heights_mm), self._hover[face]
                lo, hi = (float(a) for a in np.log(self.spec.height_range_mm))
            k = x.size - 1
            self._splines[key] = _spline(
                [(u, min(3, u.size - 1), None), (v, min(3, v.size - 1), None),
                 (x, k, _clamped(lo, hi, k))],
                values,
            )
        return self._splines[key]

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the field to ``path`` (.npz) atomically: the spec (JSON), the key, the node
        values and the untouched readout; :meth:`from_file` rebuilds it from that file alone."""
        arrays: dict[str, Any] = {
            "format": np.array(FIELD_FORMAT),
            "key": np.array(self.key),
            "spec_json": np.array(json.dumps(self.spec.to_dict(), sort_keys=True)),
            "untouched": self.untouched,
        }
        for face in self.faces:
            arrays[f"contact_{face}"] = self._contact[face]
            if face in self._hover:
                arrays[f"hover_{face}"] = self._hover[face]

        def write(fh) -> None:
            buf = io.BytesIO()
            np.savez(buf, **arrays)
            fh.write(buf.getvalue())

        return atomic_write(path, write, what="the response field")

    @classmethod
    def from_file(cls, path: str | os.PathLike) -> ResponseField:
        """A field written by :meth:`save`."""
        path = Path(os.fspath(path))
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except FileNotFoundError:
            raise EctskinError(f"{path}: response field not found") from None
        except (OSError, ValueError) as exc:
            raise EctskinError(f"{path}: not a response field file ({exc})") from None
        for name in ("format", "key", "spec_json", "untouched"):
            if name not in data:
                raise EctskinError(f"{path}: not a response field file (no {name!r})")
        if int(data["format"]) != FIELD_FORMAT:
            raise EctskinError(
                f"{path}: response field format {int(data['format'])}, this ectskin reads "
                f"{FIELD_FORMAT}; build the field again"
            )
        spec = FieldSpec.from_dict(json.loads(str(data["spec_json"])), source=str(path))
        contact = {f: data[f"contact_{f}"] for f in spec.face_names if f"contact_{f}" in data}
        hover = {f: data[f"hover_{f}"] for f in spec.face_names if f"hover_{f}" in data}
        return cls(spec, data["untouched"], contact, hover, key=str(data["key"]))


def _values(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    if value is None:
        raise EctskinError(f"ResponseField: {name} is missing (expected shape {shape})")
    arr = np.array(value, dtype=np.float64)
    if arr.shape != shape:
        raise EctskinError(f"ResponseField: {name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise EctskinError(f"ResponseField: {name} holds NaN or inf")
    arr.setflags(write=False)
    return arr


def _within(name: str, x: np.ndarray, lo: float, hi: float, where: str) -> None:
    if x.size and (x.min() < lo - _EDGE_TOL or x.max() > hi + _EDGE_TOL):
        bad = x[(x < lo - _EDGE_TOL) | (x > hi + _EDGE_TOL)][0]
        raise EctskinError(
            f"response field: {name} = {bad:.6g} lies outside the field's range "
            f"[{lo:.6g}, {hi:.6g}] ({where}); build a field that covers it"
        )
