"""The live engine's physical-inversion head: the fingers fitted to each frame through the
response fields (:mod:`ectskin.inversion`), no trained model.

:class:`InversionHead` (``inversion``) fits every ``every``-th frame that has a touch reference
with :meth:`Inversion.fit <ectskin.inversion.Inversion.fit>` and writes an
:class:`~ectskin.live.output.InversionFrame` (per finger: face, pressing or hovering, u, v,
force or height, and their standard errors; the count's BIC) into the output.

* **The state**: a field describes one inflation state, so each frame is fitted through the
  field of its state: the frame's own inflation when the source carries it (a replay, the
  twin: what the pump set), else the head's fixed ``state`` (``ectskin live --state``). A frame
  of a state without a field is refused (:class:`EctskinError` naming the state and the states
  there are fields of; the engine counts it in ``stats["errors"]``), and so is, at the door
  (:meth:`InversionHead.bind`), a replay with a trial of such a state.
* **The readout**: ``"absolute"`` fits the raw frame in pF (the fields' own unit: a source
  calibrated like the twin); ``"difference"`` fits c − c_0 against the touch reference (the
  untouched readout of the field's state is added back: a source whose changes match the twin's
  and whose absolute values do not; valid while the reference was captured at the frame's
  state).
* **Warm start**: a live stream is continuous, so each fit starts from the previous fitted
  frame's answer (``Inversion.fit(warm=...)``) while the state stays the same: the coarse
  search of that count is skipped while the fit from there explains the frame within the noise.

:func:`load_fields` reads the fields: a field folder or ``field.npz`` each, or a folder of
cached fields (the field cache of :mod:`ectskin.twin.field_build`: one folder per field).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout
from ectskin.live.heads import ReferenceInUse
from ectskin.live.output import InversionFrame, Output

if TYPE_CHECKING:
    from ectskin.inversion import Inversion, InversionResult
    from ectskin.twin.field import ResponseField

#: what the head fits: the raw frame, or its change against the touch reference
READOUTS = ("absolute", "difference")
#: two states are one when every chamber differs by less than this (ml; the inversion's own)
STATE_TOL_ML = 1e-6
# The inversion and the field's files are imported where used: ``import ectskin.live`` (every
# live command, the dashboard) stays as quick as it was without the inversion head (SciPy's
# optimisers and statistics take most of a second to import).


def load_fields(paths: str | os.PathLike | Sequence[str | os.PathLike]
                ) -> dict[tuple[float, ...], ResponseField]:
    """The response fields at ``paths``, state → field: each path a field folder (with
    ``field.npz``), a ``field.npz``, or a folder of field folders (a field cache: every complete
    field in it). Two fields of one state, or none at all, are refused."""
    from ectskin.twin.field_build import FIELD_FILE, load_field

    if isinstance(paths, str | os.PathLike):
        paths = [paths]
    files: list[Path] = []
    for p in (Path(os.fspath(x)) for x in paths):
        if p.is_file() or (p / FIELD_FILE).is_file():
            files.append(p)
        elif p.is_dir():
            found = sorted(d for d in p.iterdir() if (d / FIELD_FILE).is_file())
            if not found:
                raise EctskinError(
                    f"--fields {p}: neither a response field ({FIELD_FILE}) nor a folder of "
                    "response fields (none of its folders holds a complete field)"
                )
            files.extend(found)
        else:
            raise EctskinError(f"--fields {p}: no such file or folder")
    fields: dict[tuple[float, ...], ResponseField] = {}
    where: dict[tuple[float, ...], Path] = {}
    for f in files:
        field = load_field(f)
        state = tuple(float(x) for x in field.spec.inflation_ml)
        twin = next((s for s in fields if _same(s, state)), None)
        if twin is not None:
            raise EctskinError(
                f"--fields: {where[twin]} and {f} are both fields of state {list(state)} ml; "
                "give one field per inflation state"
            )
        fields[state], where[state] = field, f
    return fields


class InversionHead:
    """The physical inversion bound to ``layout`` (module docstring).

    Parameters
    ----------
    inversion : an :class:`~ectskin.inversion.Inversion` over the fields of the states the
        stream visits (their pairs in the layout's order).
    layout : the sensor layout of the stream.
    state : the inflation (ml per chamber) of frames that do not carry theirs, or None.
    every : fit every ``every``-th frame that has a reference (1: all).
    readout : "absolute" or "difference" (module docstring).
    warm : start each fit from the previous fitted frame's answer (module docstring).
    fields : state → the field (its faces' extents for the dashboard's ``meta``), optional.
    """

    key, what, reference, window = "inversion", "physical inversion", "touch", 1

    def __init__(
        self,
        inversion: Inversion,
        layout: SensorLayout,
        *,
        state: Any = None,
        every: int = 1,
        readout: str = "absolute",
        warm: bool = True,
        fields: Mapping[tuple[float, ...], Any] | None = None,
    ) -> None:
        from ectskin.inversion import Inversion

        what = self.what
        if not isinstance(inversion, Inversion):
            raise EctskinError(f"{what}: inversion must be an Inversion, got {type(inversion).__name__}")
        if inversion.n_pairs != layout.n_pairs:
            raise EctskinError(
                f"{what}: the fields have {inversion.n_pairs} pairs, layout {layout.name!r} has "
                f"{layout.n_pairs}"
            )
        if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
            raise EctskinError(f"{what}: every must be an integer >= 1 (frames), got {every!r}")
        if readout not in READOUTS:
            raise EctskinError(
                f"Invalid value for 'readout': allowed values are {list(READOUTS)}; got {readout!r}"
            )
        self.inversion = inversion
        self.layout = layout
        self.every = int(every)
        self.readout = readout
        self.warm = bool(warm)
        self.state: tuple[float, ...] | None = None
        if state is not None:
            self.state = self._known("--state", state)
        self.faces = sorted({f for m in (inversion.model(s) for s in inversion.states)
                             for f in m.faces})
        self.face_extent: dict[str, list[list[float]]] = {}
        for fld in (fields or {}).values():
            for face in fld.faces:
                self.face_extent.setdefault(face, [list(map(float, e)) for e in fld.spec.extent(face)])
        self._calls = 0
        self._last: InversionResult | None = None
        self._last_state: tuple[float, ...] | None = None

    @classmethod
    def from_fields(cls, fields: Mapping[tuple[float, ...], ResponseField] | str | os.PathLike
                    | Sequence[str | os.PathLike], layout: SensorLayout, *, max_fingers: int = 2,
                    **kw: Any) -> InversionHead:
        """The head over ``fields`` (state → field, or the paths of :func:`load_fields`),
        refused unless they are fields of ``layout`` (the same pairs in the same order)."""
        from ectskin.inversion import Inversion

        if not isinstance(fields, Mapping):
            fields = load_fields(fields)
        for state, fld in fields.items():
            fl = fld.spec.layout
            if tuple(fl.pair_names) != tuple(layout.pair_names):
                raise EctskinError(
                    f"--fields: the field of state {list(state)} ml is of layout {fl.name!r} "
                    f"({fl.n_pairs} pairs), the stream's layout is {layout.name!r} "
                    f"({layout.n_pairs} pairs) with other pairs"
                )
        return cls(Inversion(fields, max_fingers=max_fingers), layout, fields=fields, **kw)

    # ------------------------------------------------------------------ states
    @property
    def states(self) -> list[tuple[float, ...]]:
        """The states there are fields of."""
        return list(self.inversion.states)

    def _known(self, name: str, state: Any) -> tuple[float, ...]:
        """``state`` as a tuple, refused unless a field of it is loaded."""
        try:
            s = tuple(float(x) for x in np.atleast_1d(np.asarray(state, dtype=np.float64)))
        except (TypeError, ValueError):
            raise EctskinError(f"{self.what}: {name} must be an inflation vector (ml), got {state!r}") from None
        if not any(_same(s, k) for k in self.inversion.states):
            raise EctskinError(
                f"{self.what}: no response field for {name} {list(s)} ml; the fields cover "
                f"{[list(k) for k in self.inversion.states]} (build or pass the field of this "
                "state with --fields)"
            )
        return s

    def bind(self, source: Any) -> None:
        """Refuse a source whose frames are known before they come (a replay's trials) to visit
        a state without a field, or to carry no state when the head has none."""
        trials = getattr(source, "trials", None)
        if not trials:
            return
        missing: dict[tuple[float, ...] | None, list[str]] = {}
        for t in trials:
            infl = getattr(t, "inflation", None)
            s = tuple(float(x) for x in infl) if infl is not None and len(infl) else None
            if s is None and self.state is not None:
                continue
            if s is None or not any(_same(s, k) for k in self.inversion.states):
                missing.setdefault(s, []).append(str(getattr(t, "name", "?")))
        if missing:
            say = "; ".join(
                f"{'no state' if s is None else list(s)} ml ({len(n)} trial(s), e.g. {n[0]!r})"
                for s, n in missing.items()
            )
            raise EctskinError(
                f"{self.what}: {getattr(source, 'name', 'the source')} has trials of states without a "
                f"response field: {say}; the fields cover "
                f"{[list(k) for k in self.inversion.states]}"
            )

    def state_of(self, out: Output) -> tuple[float, ...]:
        """The state of the frame of ``out``: its own inflation, else the head's ``state``."""
        if out.inflation is not None and len(out.inflation):
            return self._known("the frame's inflation", out.inflation)
        if self.state is None:
            raise EctskinError(
                f"{self.what}: frame {out.seq} carries no inflation state and no --state was "
                "given; pass the state the skin is inflated to"
            )
        return self.state

    # ------------------------------------------------------------------ frames
    def due(self) -> bool:
        """True on the 1st, (every+1)-th, … call: whether this frame is fitted."""
        due = self._calls % self.every == 0
        self._calls += 1
        return due

    def __call__(self, raw: np.ndarray, c0: np.ndarray, state: tuple[float, ...]) -> InversionFrame:
        """The inversion of one raw frame (n_pairs,) pF of ``state``; the touch reference
        ``c0`` (n_pairs,) pF is used by ``readout="difference"``."""
        raw = np.asarray(raw, dtype=np.float64)
        if self.readout == "difference":
            y, kind = raw - np.asarray(c0, dtype=np.float64), "difference"
        else:
            y, kind = raw, "absolute"
        y = np.where(np.isfinite(y), y, np.nan)  # a channel without a usable value is masked
        warm = self._last if self.warm and self._last_state == state else None
        t0 = time.perf_counter()
        try:
            r = self.inversion.fit(y, state, kind=kind, warm=warm)
        finally:
            self._last = None  # a failed fit starts the next one cold
        ms = (time.perf_counter() - t0) * 1e3
        if r.n_fingers:
            self._last, self._last_state = r, state
        return InversionFrame(
            state=state, n_fingers=r.n_fingers, fingers=r.fingers,
            bic_by_count=r.bic_by_count, converged=r.converged, warm=warm is not None,
            fit_ms=ms,
        )

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        if self.due():
            out.inversion = self(frames[-1], ref.c0, self.state_of(out))

    def meta(self) -> dict[str, Any]:
        return {
            "states": [list(s) for s in self.states],
            "faces": self.faces,
            "face_extent": self.face_extent,
            "every": self.every,
            "readout": self.readout,
            "max_fingers": self.inversion.max_fingers,
            "warm": self.warm,
        }


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return len(a) == len(b) and all(
        math.isclose(x, y, rel_tol=0.0, abs_tol=STATE_TOL_ML) for x, y in zip(a, b)
    )
