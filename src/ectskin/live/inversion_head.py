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
* **The readout**: ``"reference"`` (:meth:`InversionHead.from_fields`' and ``ectskin live``'s
  default) fits the raw frame in pF with the skin's own untouched readout in place of the
  field's: the touch reference c_0, which the engine captures with the skin untouched (the
  fingers' signals stay the field's). It is the reproduction's ``untouched="auto"``
  (:mod:`ectskin.pipeline.inversion`, the mean of the recording's no-contact frames of the
  state), with the live stream's own untouched frames as the measurement, and it is what a real
  skin needs: a skin's body differs from the field's mesh by far more than the noise, in a
  pattern over the channels that the fit's common gain and offset cannot take up.
  c_0 is the untouched readout of the state it was captured at: the rest state (all chambers at
  0 ml) when the frames carry their inflation (the engine refuses a touch reference captured
  inflated), else the head's ``state``. A frame of another state is fitted with
  c_0 + (c_u,field(frame's state) − c_u,field(c_0's state)), the skin's offset from the field
  carried over; where c_0's state has no field, with the field's own untouched readout. The
  inversion of a state is rebuilt when the reference changes (once per reference and state,
  tens of ms: the untouched readout is fixed when an :class:`~ectskin.inversion.Inversion` is
  built). ``"absolute"`` fits the raw frame against the field's untouched readout (a source
  calibrated like the field's mesh); ``"difference"`` fits c − c_0 + c_u,field (a source whose
  changes match the twin's and whose absolute values do not). "difference" takes the same
  offsets off as "reference" but is not the same fit: its gain nuisance column is the field's
  c_u instead of c_0, and the noise σ (which grows with the readout) and the coarse search's
  whitening are evaluated at the frame shifted onto the field's base instead of at the frame
  itself, which changes χ², the weights and the BIC's Σ ln σ (by about the offsets' share of
  the readout).
* **The fit's options**: :meth:`InversionHead.from_fields` builds the inversion as the
  reproduction's step does (:mod:`ectskin.pipeline.reproduce`): ``press_check=True`` (a
  hovering finger refitted pressing, kept when that fits about as well) and
  ``finger_scale_sd`` = :data:`ectskin.inversion.fit.FINGER_SCALE_SD` (people's fingertips
  differ from the field's), so a frame gets the live and the offline answer alike.
* **Warm start**: a live stream is continuous, so each fit starts from the previous fitted
  frame's answer (``Inversion.fit(warm=...)``) while the state stays the same: the coarse
  search of that count is skipped while the fit from there explains the frame within the noise.
* **The person's finger** (``person``, with an inversion of finger tables: ``from_fields(
  finger_tables=...)``, :func:`ectskin.twin.field_finger.finger_tables`): a person's pulp
  modulus and fingertip radius do not change from frame to frame, so the head pools what the
  frames tell of them as they come (:class:`ectskin.inversion.FingerPool`) and fits each frame
  with the pool so far as its prior, the reproduction's ``finger`` pooling done online (there
  every frame of a trial is fitted twice; here each frame once, with what the frames before it
  told). ``"session"``: one person for the stream until :meth:`InversionHead.new_person`;
  ``"trial"``: a new person whenever the frame's trial changes (a replay of a recording whose
  trials are each one person's, as the twin's are); ``"off"``: each frame with the
  population's prior. The pool rides in the message (:class:`~ectskin.live.output.
  InversionFrame` ``finger``).
* **The standard errors' model error** (``bound_error``): the field does not describe a skin
  to its noise (its mesh, the person's fingertip, the hand), so the readout noise alone makes
  standard errors that are too small (:mod:`ectskin.inversion.model_error`). ``"session"``
  learns the floor (a, r) from the stream's own fits, no labels: the residuals of the last
  :data:`BOUND_ERROR_WINDOW` fitted frames, estimated once :data:`BOUND_ERROR_FIRST` have
  come and again every :data:`BOUND_ERROR_EVERY` (:class:`ectskin.inversion.
  RunningModelError`); from then on each frame's points', forces' and heights' standard
  errors carry it (:meth:`Inversion.with_bound_error <ectskin.inversion.Inversion.
  with_bound_error>`; the fits are unchanged). A pair (a pF, r) gives a known floor (the
  reproduction's ``inversion.model_error`` of the same skin); ``"off"``: the noise alone. The
  floor in use rides in the message (``model_error``).

:func:`load_fields` reads the fields: a field folder or ``field.npz`` each, or a folder of
cached fields (the field cache of :mod:`ectskin.twin.field_build`: one folder per field).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
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

#: what the head fits: the raw frame against the touch reference as the untouched readout, the
#: raw frame against the field's, or its change against the touch reference (module docstring)
READOUTS = ("reference", "absolute", "difference")
#: whose finger the frames are (module docstring): one person per stream, per trial, or none pooled
PERSONS = ("off", "session", "trial")
#: the standard errors' model error (module docstring): none, learnt from the session's fits
BOUND_ERRORS = ("off", "session")
#: ``bound_error="session"``: the fitted frames before the first estimate, between estimates,
#: and the most the estimate reads (:class:`ectskin.inversion.RunningModelError`)
BOUND_ERROR_FIRST, BOUND_ERROR_EVERY, BOUND_ERROR_WINDOW = 100, 100, 1000
#: ``finger_scale_sd``'s default in :meth:`InversionHead.from_fields`: the reproduction's,
#: :data:`ectskin.inversion.fit.FINGER_SCALE_SD` (imported there: see below)
REPRODUCTION = "reproduction"
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
    readout : "reference", "absolute" or "difference" (module docstring). "absolute" (the
        default here) fits through ``inversion`` as it was built; "reference" rebuilds it per
        touch reference with ``rebuild`` (:meth:`from_fields` gives it and makes "reference"
        the default).
    warm : start each fit from the previous fitted frame's answer (module docstring).
    fields : state → the field (its faces' extents for the dashboard's ``meta``), optional.
    rebuild : ``rebuild(state, untouched)``: the inversion of ``state`` with the untouched
        readout ``untouched`` (n_pairs,) pF, built with ``inversion``'s options (readout
        "reference"); None: none (then "reference" is refused).
    person : "off", "session" or "trial": the person's finger pooled over the frames (module
        docstring); needs ``inversion`` built with finger tables.
    bound_error : "off", "session" or (a pF, r): the standard errors' model error (module
        docstring).
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
        rebuild: Callable[[tuple[float, ...], np.ndarray], Inversion] | None = None,
        person: str = "off",
        bound_error: str | tuple[float, float] = "off",
    ) -> None:
        from ectskin.inversion import FingerPool, Inversion, RunningModelError
        from ectskin.inversion.noise import check_floor

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
        if readout == "reference" and rebuild is None:
            raise EctskinError(
                f"{what}: readout 'reference' rebuilds the inversion with the touch reference as "
                "the untouched readout: give rebuild (InversionHead.from_fields does)"
            )
        if person not in PERSONS:
            raise EctskinError(
                f"Invalid value for 'person': allowed values are {list(PERSONS)}; got {person!r}"
            )
        if person != "off" and not inversion.finger_prior_sd:
            raise EctskinError(
                f"{what}: person {person!r} pools the person's finger, and the inversion fits "
                "none: build it with finger tables (InversionHead.from_fields(finger_tables=...), "
                "ectskin live --inversion-person)"
            )
        self.learn = None
        self.floor: tuple[float, float] | None = None
        if isinstance(bound_error, str):
            if bound_error not in BOUND_ERRORS:
                raise EctskinError(f"Invalid value for 'bound_error': allowed values are "
                                   f"{list(BOUND_ERRORS)} or (a pF, r); got {bound_error!r}")
            if bound_error == "session":
                self.learn = RunningModelError(BOUND_ERROR_FIRST, BOUND_ERROR_EVERY,
                                               BOUND_ERROR_WINDOW)
        else:
            self.floor = check_floor("bound_error", bound_error)
        self.bound_error = bound_error
        self.inversion = inversion
        self.layout = layout
        self.person = person
        self.pool = None if person == "off" else FingerPool(inversion.finger_prior_sd)
        self._trial: str | None = None
        self.every = int(every)
        self.readout = readout
        self.warm = bool(warm)
        self.rebuild = rebuild
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
        #: readout "reference": per state, (the c_0 it was built for, the reference's state,
        #: its inversion or None for the base one, the channels masked)
        self._built: dict[tuple[float, ...], tuple[np.ndarray, tuple[float, ...],
                                                   Inversion | None, np.ndarray]] = {}

    @classmethod
    def from_fields(cls, fields: Mapping[tuple[float, ...], ResponseField] | str | os.PathLike
                    | Sequence[str | os.PathLike], layout: SensorLayout, *, max_fingers: int = 2,
                    press_check: bool = True, finger_scale_sd: float | str | None = REPRODUCTION,
                    readout: str = "reference",
                    finger_tables: Mapping[str, Mapping[tuple[float, ...], Any]] | None = None,
                    **kw: Any) -> InversionHead:
        """The head over ``fields`` (state → field, or the paths of :func:`load_fields`),
        refused unless they are fields of ``layout`` (the same pairs in the same order).

        The inversion is built as the reproduction's step builds it (module docstring):
        ``press_check`` (default True), ``finger_scale_sd`` (default :data:`REPRODUCTION`:
        :data:`ectskin.inversion.fit.FINGER_SCALE_SD`; None or 0: no scale) and the readout
        "reference" (the touch reference as the untouched readout). ``finger_tables``:
        {"modulus" | "radius": {state: table}} (:func:`ectskin.twin.field_finger.
        finger_tables`), each pressing finger's nuisances fitted (and pooled: ``person``)."""
        from ectskin.inversion import Inversion
        from ectskin.inversion.fit import FINGER_SCALE_SD

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
        if not isinstance(press_check, bool):
            raise EctskinError(f"--inversion-press-check must be True or False, got {press_check!r}")
        if isinstance(finger_scale_sd, str):
            if finger_scale_sd != REPRODUCTION:
                raise EctskinError(
                    f"--inversion-finger-sd must be a number >= 0 (0: off) or {REPRODUCTION!r}, "
                    f"got {finger_scale_sd!r}"
                )
            finger_scale_sd = FINGER_SCALE_SD
        if finger_scale_sd is not None:
            sd = finger_scale_sd
            if isinstance(sd, bool) or not isinstance(sd, int | float) or not 0 <= sd < math.inf:
                raise EctskinError(f"--inversion-finger-sd must be a number >= 0 (0: off), got {sd!r}")
            finger_scale_sd = float(sd) or None
        options: dict[str, Any] = {"max_fingers": max_fingers, "press_check": press_check,
                                   "finger_scale_sd": finger_scale_sd}
        if finger_tables is not None:
            unknown = (sorted(set(finger_tables) - {"modulus", "radius"})
                       if isinstance(finger_tables, Mapping) else type(finger_tables).__name__)
            if unknown:
                raise EctskinError(f"finger_tables must be {{'modulus' | 'radius': {{state: "
                                   f"table}}}}, got {unknown}")
            options.update(finger_tables)
        base = dict(fields)

        def rebuild(state: tuple[float, ...], untouched: np.ndarray) -> Inversion:
            fld = next(f for s, f in base.items() if _same(tuple(float(x) for x in s), state))
            return Inversion({state: fld}, untouched={state: untouched}, **options)

        return cls(Inversion(fields, **options), layout, fields=fields, readout=readout,
                   rebuild=rebuild, **kw)

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

    def __call__(self, raw: np.ndarray, c0: np.ndarray, state: tuple[float, ...], *,
                 reference_state: tuple[float, ...] | None = None) -> InversionFrame:
        """The inversion of one raw frame (n_pairs,) pF of ``state``; the touch reference
        ``c0`` (n_pairs,) pF (NaN: a channel without a usable reference) is used by the readouts
        "reference" and "difference"; ``reference_state``: the state ``c0`` was captured at
        (None: ``state``; readout "reference")."""
        raw = np.asarray(raw, dtype=np.float64)
        inversion = self.inversion
        if self.readout == "difference":
            y, kind = raw - np.asarray(c0, dtype=np.float64), "difference"
        else:
            y, kind = raw, "absolute"
        if self.readout == "reference":
            at = state if reference_state is None else reference_state
            inv, masked = self._with_reference(np.asarray(c0, dtype=np.float64), state,
                                               tuple(float(x) for x in at))
            if inv is not None:
                inversion = inv
            if masked.any():
                y = np.where(masked, np.nan, y)
        y = np.where(np.isfinite(y), y, np.nan)  # a channel without a usable value is masked
        warm = self._last if self.warm and self._last_state == state else None
        prior = None if self.pool is None else self.pool.prior()
        learnt = None if self.learn is None else self.learn.estimate  # before this frame
        floor = self.floor if learnt is None else learnt.floor
        fitting = inversion if floor is None else inversion.with_bound_error(floor)
        t0 = time.perf_counter()
        try:
            r = fitting.fit(y, state, kind=kind, warm=warm, finger=prior)
        finally:
            self._last = None  # a failed fit starts the next one cold
        ms = (time.perf_counter() - t0) * 1e3
        if r.n_fingers:
            self._last, self._last_state = r, state
        if self.learn is not None:  # this frame's residuals (model_error.residuals' row)
            m = inversion.model(state)
            obs, _ = inversion.observed(y, state, kind)
            self.learn.add(obs - r.fitted, m.sigma(obs, 1), obs - m.untouched, r.leverage)
        finger = None
        if self.pool is not None:
            self.pool.add(r, prior)
            finger = {**{f"{name}_ln": list(v) for name, v in self.pool.posterior().items()},
                      "frames": self.pool.n_frames}
        return InversionFrame(
            state=state, n_fingers=r.n_fingers, fingers=r.fingers,
            bic_by_count=r.bic_by_count, converged=r.converged, warm=warm is not None,
            fit_ms=ms, finger=finger,
            model_error=None if floor is None else {
                "a_pf": floor[0], "r": floor[1],
                "frames": None if learnt is None else learnt.n_frames},
        )

    def new_person(self) -> None:
        """Another person's finger from the next frame on: the pool starts again (module
        docstring)."""
        if self.pool is not None:
            self.pool.reset()

    def untouched(self, c0: np.ndarray, state: tuple[float, ...],
                  reference_state: tuple[float, ...]) -> tuple[np.ndarray | None, np.ndarray]:
        """The untouched readout (n_pairs,) pF the readout "reference" fits a frame of
        ``state`` with, from the touch reference ``c0`` captured at ``reference_state`` (module
        docstring), and the channels it masks (bool, (n_pairs,): no usable reference, or not a
        readout > 0); (None, none masked) where it has none (``reference_state`` has no field:
        the field's own)."""
        c0 = np.asarray(c0, dtype=np.float64)
        if c0.shape != (self.inversion.n_pairs,):
            raise EctskinError(
                f"{self.what}: the touch reference must be ({self.inversion.n_pairs},) pF, got "
                f"shape {c0.shape}"
            )
        field_u = self.inversion.model(state).field_untouched
        if _same(tuple(reference_state), tuple(state)):
            cu = c0.copy()
        elif any(_same(tuple(reference_state), k) for k in self.inversion.states):
            cu = c0 + (field_u - self.inversion.model(reference_state).field_untouched)
        else:
            return None, np.zeros(c0.shape, bool)
        masked = ~(np.isfinite(cu) & (cu > 0))
        cu[masked] = field_u[masked]  # left out of the fit: any readout > 0 builds
        return cu, masked

    def _with_reference(self, c0: np.ndarray, state: tuple[float, ...],
                        reference_state: tuple[float, ...]
                        ) -> tuple[Inversion | None, np.ndarray]:
        """The inversion of ``state`` with the untouched readout of :meth:`untouched` (built
        once per reference and state) and the channels masked."""
        got = self._built.get(state)
        if (got is not None and got[1] == reference_state
                and np.array_equal(got[0], c0, equal_nan=True)):
            return got[2], got[3]
        cu, masked = self.untouched(c0, state, reference_state)
        assert self.rebuild is not None  # readout "reference" has it (checked at __init__)
        inv = None if cu is None else self.rebuild(state, cu)
        self._built[state] = (c0.copy(), reference_state, inv, masked)
        return inv, masked

    def step(self, frames: np.ndarray, ref: ReferenceInUse, out: Output) -> None:
        if self.person == "trial" and out.trial != self._trial:
            self._trial = out.trial
            self.new_person()
        if self.due():
            state = self.state_of(out)
            # the engine refuses a touch reference captured inflated: with the frames' own
            # inflation known, c_0 is the rest state's; else the skin stays at --state
            carried = out.inflation is not None and len(out.inflation) > 0
            rest = tuple(0.0 for _ in state) if carried else state
            out.inversion = self(frames[-1], ref.c0, state, reference_state=rest)

    def meta(self) -> dict[str, Any]:
        inv = self.inversion
        return {
            "states": [list(s) for s in self.states],
            "faces": self.faces,
            "face_extent": self.face_extent,
            "every": self.every,
            "readout": self.readout,
            "max_fingers": inv.max_fingers,
            "press_check": inv.press_check,
            "finger_scale_sd": inv.finger_scale_sd,
            "warm": self.warm,
            "person": self.person,
            "finger_nuisances": list(inv.finger_prior_sd),
            "bound_error": (self.bound_error if isinstance(self.bound_error, str)
                            else list(self.floor or ())),
        }


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return len(a) == len(b) and all(
        math.isclose(x, y, rel_tol=0.0, abs_tol=STATE_TOL_ML) for x, y in zip(a, b)
    )
