"""In-memory recordings: a :class:`Recording` holds a layout and a list of :class:`Trial`.

A trial is one contiguous group of frames (30 s in the paper's protocol). Arrays and their
metadata are checked against each other when a trial is built, so downstream code can trust
shapes and units (F = n_frames, K = n_fingers):

======================  =============================  ======================================
field                   shape                          meaning
======================  =============================  ======================================
``capacitance``         (F, n_pairs) float64           raw readout per pair, pF (NaN = masked)
``timestamps``          (F,) float64                   seconds from the start of the trial
``labels``              (F,) int16                     touch class per frame, 0 = no touch
``markers``             (F, n_markers, 3) float64      marker positions, mm, NaN where occluded
``force``               (F, K) float64                 each finger's normal force, N
``contact``             (F, K) bool                    the finger is on the skin
``finger_uv_mm``        (F, K, 2) float64              skin point under each fingertip, mm
``finger_height_mm``    (F, K) float64                 each fingertip's height above the skin
``finger_surface``      K faces (tuple)                the face each finger is on or over
``finger_radius_mm``    (K,) float64                   each fingertip's radius, mm
``finger_modulus_mpa``  (K,) float64                   each fingertip pulp's modulus, MPa
======================  =============================  ======================================

``markers`` and the per-frame finger fields (``force``, ``contact``, ``finger_uv_mm``,
``finger_height_mm``) may each be ``None`` (not recorded). ``inflation`` is the chamber volume
vector p in ml (finite, >= 0), ``region`` the trial's touched region (0 for none).

**The fingers axis.** Every finger field covers the same K fingers, in one order (finger 0 is
the one the ``labels`` follow). K is :attr:`Trial.n_fingers` (0 when no finger field is given);
:meth:`Trial.finger` gives finger k's fields alone. One finger may be given without the axis
(``contact`` (F,), ``finger_uv_mm`` (F, 2), ``force`` (F,), ``finger_height_mm`` (F,), a face
name as ``finger_surface``): the trial stores it on the axis (K = 1). ``finger_surface`` holds
one face name or None (not given) per finger; ``finger_radius_mm`` and ``finger_modulus_mpa``
are None (unknown for every finger) or (K,) with NaN where unknown.

**The ground truth** (:data:`GROUND_TRUTH_FIELDS`) says where each finger is in every frame, in
contact or hovering: ``finger_uv_mm`` is the point of the skin under the fingertip in the surface
coordinates (u, v) of the finger's face ((x, z) on ``front``/``back``, see
:mod:`ectskin.layout.layout`), ``finger_height_mm`` the fingertip's height above the skin. Rules
per finger and frame, checked by :func:`check_fingers`:

* a point is two finite numbers or two NaN; a height is >= 0 or NaN; where both are given they
  are NaN in the same frames, those in which the finger is away (not over the skin);
* in contact the point is known and the height is 0;
* a force is >= 0 or NaN (unknown), and 0 or NaN in the frames without contact;
* faces are those of :data:`~ectskin.layout.layout.SURFACES`; radius and modulus > 0 or NaN.

:attr:`Trial.n_contacts` counts the fingers on the skin per frame; :func:`require_ground_truth`
refuses a recording without the ground truth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array, check_option
from ectskin.layout import SensorLayout
from ectskin.layout.layout import SURFACES

#: The per-frame finger ground truth of a :class:`Trial` (each optional, all three needed).
GROUND_TRUTH_FIELDS = ("contact", "finger_uv_mm", "finger_height_mm")
#: The per-frame fields on the fingers axis: name → shape of one finger in one frame.
FINGER_FRAME_FIELDS: dict[str, tuple[int, ...]] = {
    "force": (),
    "contact": (),
    "finger_uv_mm": (2,),
    "finger_height_mm": (),
}
#: The per-trial numbers of each finger, (n_fingers,) float64, NaN = unknown.
FINGER_TRIAL_FIELDS = ("finger_radius_mm", "finger_modulus_mpa")


def check_name(what: str, name: Any) -> str:
    """A name stored in a recording (trial, event text): a non-empty ``str`` without NUL bytes,
    which HDF5's strings cannot hold."""
    if not isinstance(name, str):
        raise EctskinError(f"{what} must be a str, got {type(name).__name__} ({name!r:.60})")
    if not name:
        raise EctskinError(f"{what} must not be empty")
    if "\x00" in name:
        raise EctskinError(f"{what} {name!r} contains a NUL byte, which a recording cannot store")
    return name


def _index(mask: np.ndarray) -> tuple[int, ...]:
    """The first index where ``mask`` is true, as ints."""
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _at(k: tuple[int, ...]) -> str:
    return "[" + ", ".join(map(str, k)) + "]"


def finger_frames(name: str, value: Any, n: int, src: str) -> np.ndarray:
    """``value`` of the per-frame finger field ``name`` on the fingers axis: (n, K, *tail).

    Taken as given, or, for one finger without the axis, (n, *tail) → (n, 1, *tail); ``contact``
    as bool (bools or the numbers 0/1), the others as float64. Errors name ``src`` and ``name``.
    """
    tail = FINGER_FRAME_FIELDS[name]
    try:
        arr = np.asarray(value)
        if name != "contact":
            arr = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{src}: {name} must be numeric; {exc}") from None
    if name == "contact" and arr.dtype != np.bool_:
        if arr.dtype.kind not in "iuf":
            raise EctskinError(f"{src}: contact must be bool, found dtype {arr.dtype}")
        bad = ~np.isin(arr, (0, 1))
        if bad.any():
            k = _index(bad)
            raise EctskinError(
                f"{src}: contact must be bool (or 0/1), found {arr[k]} at index {k}"
            )
        arr = arr.astype(np.bool_)
    one = arr.ndim == 1 + len(tail)
    if one:
        arr = arr[:, None]
    if arr.ndim != 2 + len(tail) or arr.shape[0] != n or arr.shape[2:] != tail:
        axis = ", ".join(map(str, (n, "n_fingers", *tail)))
        single = ", ".join(map(str, (n, *tail)))
        got = arr.shape[:1] + arr.shape[2:] if one else arr.shape
        raise EctskinError(
            f"{src}: {name} must have shape ({axis}) or, one finger, ({single}{',' * (not tail)})"
            f"; got {got}"
        )
    return arr


def _faces(src: str, value: Any) -> tuple[str | None, ...] | None:
    """``finger_surface`` as one face name or None per finger; None where not given."""
    if value is None:
        return None
    if isinstance(value, str):
        value = (value,)
    if not isinstance(value, Sequence | np.ndarray):
        raise EctskinError(
            f"{src}: finger_surface must be a face name or a sequence of them (one per finger), "
            f"got {type(value).__name__} ({value!r:.60})"
        )
    faces = tuple(value)
    if not faces:
        return None
    for k, face in enumerate(faces):
        if face is not None:
            check_option(f"finger_surface[{k}]", face, SURFACES, source=src)
    return tuple(None if v is None else str(v) for v in faces)


def _per_finger(src: str, name: str, value: Any, what: str) -> np.ndarray | None:
    """A per-trial number of each finger, (K,) float64: > 0 or NaN (unknown); None if not given."""
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{src}: {name} must be numeric; {exc}") from None
    if arr.ndim == 0:
        arr = arr[None]
    if arr.ndim != 1:
        raise EctskinError(f"{src}: {name} must have shape (n_fingers,), got {arr.shape}")
    bad = ~np.isnan(arr) & ~(np.isfinite(arr) & (arr > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise EctskinError(f"{src}: {name}[{k}] is {arr[k]}, expected {what} > 0 or NaN (unknown)")
    return arr


def check_fingers(src: str, n: int, **given: Any) -> dict[str, Any]:
    """The finger fields of ``n`` frames, checked and on the fingers axis (see the module).

    ``given``: any of :data:`FINGER_FRAME_FIELDS`, ``finger_surface`` and
    :data:`FINGER_TRIAL_FIELDS` (None = not given). Returns all of them: the per-frame arrays
    (n, K, ...) or None, ``finger_surface`` a tuple of K faces (None = not given), the per-trial
    numbers (K,) (NaN where unknown) or None (not given), and ``n_fingers`` K. Raises an
    :class:`EctskinError` naming ``src``, the field, the first bad [frame, finger] and what was
    expected.
    """
    unknown = set(given) - {*FINGER_FRAME_FIELDS, "finger_surface", *FINGER_TRIAL_FIELDS}
    if unknown:
        raise TypeError(f"check_fingers: unknown finger fields {sorted(unknown)}")
    out: dict[str, Any] = {
        k: None if given.get(k) is None else finger_frames(k, given[k], n, src)
        for k in FINGER_FRAME_FIELDS
    }
    faces = _faces(src, given.get("finger_surface"))
    out["finger_radius_mm"] = _per_finger(
        src, "finger_radius_mm", given.get("finger_radius_mm"), "a radius (mm)"
    )
    out["finger_modulus_mpa"] = _per_finger(
        src, "finger_modulus_mpa", given.get("finger_modulus_mpa"), "a modulus (MPa)"
    )
    counts = {k: out[k].shape[1] for k in FINGER_FRAME_FIELDS if out[k] is not None}
    counts.update({k: out[k].shape[0] for k in FINGER_TRIAL_FIELDS if out[k] is not None})
    if faces is not None:
        counts["finger_surface"] = len(faces)
    if len(set(counts.values())) > 1:
        found = ", ".join(f"{k} {v}" for k, v in counts.items())
        raise EctskinError(
            f"{src}: the finger fields disagree on the number of fingers ({found}); every "
            "finger field covers the same fingers"
        )
    K = next(iter(counts.values()), 0)
    out["n_fingers"] = K
    out["finger_surface"] = faces if faces is not None else (None,) * K
    _check_finger_values(src, out["contact"], out["finger_uv_mm"], out["finger_height_mm"])
    _check_force(src, out["force"], out["contact"])
    return out


def _check_finger_values(
    src: str, contact: np.ndarray | None, uv: np.ndarray | None, height: np.ndarray | None
) -> None:
    """The ground-truth rules per [frame, finger] (module docstring)."""
    uv_away = h_away = None
    if uv is not None:
        nan = np.isnan(uv)
        bad = np.isinf(uv).any(axis=-1) | (nan[..., 0] != nan[..., 1])
        if bad.any():
            k = _index(bad)
            raise EctskinError(
                f"{src}: finger_uv_mm{_at(k)} is {uv[k].tolist()}, expected two finite numbers "
                "(mm) or two NaN (the finger away)"
            )
        uv_away = nan[..., 0]
    if height is not None:
        h_away = np.isnan(height)
        bad = ~h_away & ~(np.isfinite(height) & (height >= 0))
        if bad.any():
            k = _index(bad)
            raise EctskinError(
                f"{src}: finger_height_mm{_at(k)} is {height[k]}, expected a height >= 0 mm "
                "(0 in contact) or NaN (the finger away)"
            )
    if uv is not None and height is not None and np.any(uv_away != h_away):
        k = _index(uv_away != h_away)
        raise EctskinError(
            f"{src}: frame {k[0]}, finger {k[1]} has finger_uv_mm {uv[k].tolist()} but "
            f"finger_height_mm {height[k]}; both are NaN in the frames without the finger, "
            "else neither"
        )
    if contact is None:
        return
    if uv_away is not None and np.any(contact & uv_away):
        k = _index(contact & uv_away)
        raise EctskinError(
            f"{src}: finger_uv_mm{_at(k)} is {uv[k].tolist()} in contact, expected two finite "
            "numbers (mm): in contact the point under the fingertip is known"
        )
    if height is not None and np.any(contact & (height != 0)):
        k = _index(contact & (height != 0))
        raise EctskinError(
            f"{src}: finger_height_mm{_at(k)} is {height[k]} in contact, expected 0 (the height "
            "in contact)"
        )


def _check_force(src: str, force: np.ndarray | None, contact: np.ndarray | None) -> None:
    """Forces >= 0 N or NaN (unknown); 0 or NaN where the finger is not in contact."""
    if force is None:
        return
    known = ~np.isnan(force)
    bad = known & ~(np.isfinite(force) & (force >= 0))
    if bad.any():
        k = _index(bad)
        raise EctskinError(f"{src}: force{_at(k)} is {force[k]}, expected a force >= 0 N or NaN")
    if contact is not None:
        bad = known & ~contact & (force != 0)
        if bad.any():
            k = _index(bad)
            raise EctskinError(
                f"{src}: force{_at(k)} is {force[k]} without contact (contact{_at(k)} False), "
                "expected 0 or NaN"
            )


def check_inflation(src: str, inflation: Any) -> tuple[float, ...]:
    """The chamber volumes p in ml: finite numbers >= 0 (any count, also none)."""
    try:
        values = tuple(float(v) for v in inflation)
    except (TypeError, ValueError):
        raise EctskinError(
            f"{src}: inflation must be a sequence of numbers (ml), got {inflation!r:.60}"
        ) from None
    for k, v in enumerate(values):
        if not (np.isfinite(v) and v >= 0):
            raise EctskinError(
                f"{src}: inflation[{k}] is {v} ml, expected a finite volume >= 0 ml"
            )
    return values


@dataclass(frozen=True)
class FingerTruth:
    """One finger of a trial (:meth:`Trial.finger`): its per-frame fields (n_frames,) (``uv_mm``
    (n_frames, 2)), None where the trial does not record them, and its per-trial properties."""

    index: int
    surface: str | None
    radius_mm: float
    modulus_mpa: float
    contact: np.ndarray | None
    uv_mm: np.ndarray | None
    height_mm: np.ndarray | None
    force: np.ndarray | None


@dataclass
class Trial:
    """One trial of frames with its labels and fingers; validated on construction (module
    docstring: the fields, the fingers axis and its rules)."""

    name: str
    capacitance: np.ndarray
    timestamps: np.ndarray
    labels: np.ndarray
    inflation: tuple[float, ...] = ()
    region: int = 0
    markers: np.ndarray | None = None
    force: np.ndarray | None = None
    contact: np.ndarray | None = None
    finger_uv_mm: np.ndarray | None = None
    finger_height_mm: np.ndarray | None = None
    finger_surface: tuple[str | None, ...] = ()
    finger_radius_mm: np.ndarray | None = None
    finger_modulus_mpa: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        src = f"trial {self.name!r}"
        check_name("trial name", self.name)
        self.capacitance = check_array("capacitance", self.capacitance, (None, None), source=src)
        n = self.capacitance.shape[0]
        self.timestamps = check_array("timestamps", self.timestamps, (n,), finite=True, source=src)
        self.labels = check_array("labels", self.labels, (n,), dtype=np.int16, source=src)
        if self.markers is not None:
            self.markers = check_array("markers", self.markers, (n, None, 3), source=src)
        fingers = check_fingers(
            src,
            n,
            **{k: getattr(self, k) for k in (*FINGER_FRAME_FIELDS, *FINGER_TRIAL_FIELDS)},
            finger_surface=self.finger_surface,
        )
        for k in (*FINGER_FRAME_FIELDS, "finger_surface", *FINGER_TRIAL_FIELDS):
            setattr(self, k, fingers[k])
        self.inflation = check_inflation(src, self.inflation)
        self.region = int(self.region)
        if n and np.any(np.diff(self.timestamps) <= 0):
            k = int(np.argmax(np.diff(self.timestamps) <= 0)) + 1
            raise EctskinError(
                f"{src}: timestamps must increase; frame {k} has {self.timestamps[k]} after "
                f"{self.timestamps[k - 1]}"
            )

    @property
    def n_frames(self) -> int:
        return self.capacitance.shape[0]

    @property
    def n_pairs(self) -> int:
        return self.capacitance.shape[1]

    @property
    def n_markers(self) -> int:
        return 0 if self.markers is None else self.markers.shape[1]

    @property
    def n_fingers(self) -> int:
        """K, the length of the fingers axis (0 when the trial gives no finger field)."""
        return len(self.finger_surface)

    @property
    def has_occlusion(self) -> bool:
        return self.markers is not None and bool(np.isnan(self.markers).any())

    @property
    def n_contacts(self) -> np.ndarray | None:
        """(n_frames,) int64: fingers on the skin per frame; None without ``contact``."""
        if self.contact is None:
            return None
        return self.contact.sum(axis=1, dtype=np.int64)

    def finger(self, k: int) -> FingerTruth:
        """Finger ``k`` (0 .. n_fingers - 1) alone: its fields without the fingers axis."""
        integer = isinstance(k, int | np.integer) and not isinstance(k, bool)
        if not (integer and 0 <= k < self.n_fingers):
            raise EctskinError(
                f"trial {self.name!r} has {self.n_fingers} finger(s), so no finger {k!r}"
            )
        radius, modulus = self.finger_radius_mm, self.finger_modulus_mpa
        return FingerTruth(
            index=int(k),
            surface=self.finger_surface[k],
            radius_mm=math.nan if radius is None else float(radius[k]),
            modulus_mpa=math.nan if modulus is None else float(modulus[k]),
            **{
                short: None if getattr(self, name) is None else getattr(self, name)[:, k]
                for short, name in (
                    ("contact", "contact"),
                    ("uv_mm", "finger_uv_mm"),
                    ("height_mm", "finger_height_mm"),
                    ("force", "force"),
                )
            },
        )

    @property
    def has_ground_truth(self) -> bool:
        """True when the trial carries contact, finger_uv_mm and finger_height_mm."""
        return not self.missing_ground_truth

    @property
    def missing_ground_truth(self) -> tuple[str, ...]:
        """The fields of :data:`GROUND_TRUTH_FIELDS` this trial lacks (None)."""
        return tuple(k for k in GROUND_TRUTH_FIELDS if getattr(self, k) is None)


@dataclass
class Recording:
    """A layout plus trials of frames at ``frame_rate_hz``; checks that all of them agree.

    ``source`` (the file it was read from) and ``format_version`` (of that file's format) say
    where the recording came from, for messages; they are not part of its value (not compared,
    not written).
    """

    layout: SensorLayout
    trials: list[Trial]
    frame_rate_hz: float
    meta: dict[str, Any] = field(default_factory=dict)
    source: str | None = field(default=None, compare=False)
    format_version: int | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.frame_rate_hz) and self.frame_rate_hz > 0):
            raise EctskinError(f"frame_rate_hz must be > 0, got {self.frame_rate_hz!r}")
        names = set()
        for t in self.trials:
            if t.name in names:
                raise EctskinError(f"recording: duplicate trial name {t.name!r}")
            names.add(t.name)
            if t.n_pairs != self.layout.n_pairs:
                raise EctskinError(
                    f"trial {t.name!r}: capacitance has {t.n_pairs} channels, but layout "
                    f"{self.layout.name!r} has {self.layout.n_electrodes} electrodes = "
                    f"{self.layout.n_pairs} pairs"
                )
            if t.markers is not None and t.n_markers != self.layout.n_markers:
                raise EctskinError(
                    f"trial {t.name!r}: markers has {t.n_markers} markers, layout has "
                    f"{self.layout.n_markers}"
                )
            bad = (t.labels < 0) | (t.labels > self.layout.n_regions)
            if bad.any():
                k = int(np.argmax(bad))
                raise EctskinError(
                    f"trial {t.name!r}: frame {k} has label {t.labels[k]}, expected 0.."
                    f"{self.layout.n_regions}"
                )

    @property
    def n_trials(self) -> int:
        return len(self.trials)

    @property
    def n_pairs(self) -> int:
        return self.layout.n_pairs

    @property
    def n_markers(self) -> int:
        return self.layout.n_markers

    @property
    def n_frames(self) -> int:
        return sum(t.n_frames for t in self.trials)

    def trial(self, name: str) -> Trial:
        for t in self.trials:
            if t.name == name:
                return t
        raise EctskinError(f"recording has no trial {name!r}")


def require_ground_truth(rec: Recording, *, source: str | None = None) -> Recording:
    """Return ``rec`` if every trial carries the finger ground truth, else raise one clear error.

    The error names the recording (``source``, default ``rec.source``), its format version where
    known and the first trial lacking any of :data:`GROUND_TRUTH_FIELDS`, e.g. the trials of a
    format-version-1 HDF5 file, which predates them.
    """
    for t in rec.trials:
        missing = t.missing_ground_truth
        if missing:
            name = source if source is not None else rec.source
            what = "recording" + (f" {name}" if name else "")
            if rec.format_version is not None:
                what += f" (schema {rec.format_version})"
            raise EctskinError(
                f"{what} has no per-frame finger ground truth (trial {t.name!r} lacks "
                f"{', '.join(missing)}); record it again with ectskin simulate, or import labels "
                "(docs/import-format.md)"
            )
    return rec
