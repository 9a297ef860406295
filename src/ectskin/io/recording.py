"""In-memory recordings: a :class:`Recording` holds a layout and a list of :class:`Trial`.

A trial is one contiguous group of frames (30 s in the paper's protocol). Arrays and their
metadata are checked against each other when a trial is built, so downstream code can trust
shapes and units:

======================  =============================  ======================================
field                   shape                          meaning
======================  =============================  ======================================
``capacitance``         (n_frames, n_pairs) float64    raw readout per pair, pF (NaN = masked)
``timestamps``          (n_frames,) float64            seconds from the start of the trial
``labels``              (n_frames,) int16              touch class per frame, 0 = no touch
``markers``             (n_frames, n_markers, 3) f64   marker positions, mm, NaN where occluded
``force``               (n_frames,) float64            touch force, N (NaN where unknown)
``contact``             (n_frames,) bool               the finger is on the skin
``finger_uv_mm``        (n_frames, 2) float64          skin point under the fingertip, mm
``finger_height_mm``    (n_frames,) float64            fingertip height above the skin, mm
``contact2``            (n_frames,) bool               a second finger is on the skin
``finger2_uv_mm``       (n_frames, 2) float64          skin point under the second finger, mm
``force2``              (n_frames,) float64            the second finger's force, N
======================  =============================  ======================================

``markers``, ``force`` and the finger ground truth (``contact``, ``finger_uv_mm``,
``finger_height_mm``) may each be ``None`` (not recorded). ``inflation`` is the chamber volume
vector p in ml, ``region`` the trial's touched region (0 for none).

The finger ground truth describes where the finger is in every frame, in contact or hovering:
``finger_uv_mm`` is the point of the skin under the fingertip in the surface coordinates (u, v)
of ``finger_surface`` (the face the finger is on or over: (x, z) on ``front``/``back``, see
:mod:`ectskin.layout.layout`), ``finger_height_mm`` the fingertip's height above the skin. Both
are NaN in frames without a finger (the same frames for both); in contact frames the height is
0 and the point is known. :func:`require_ground_truth` refuses a recording without them.

A second finger (the twin's ``Protocol.second_finger``) has its own ground truth,
:data:`SECOND_FINGER_FIELDS`, all three or none (None: no second finger in the trial), and
``finger2_surface``, the face it presses. It exists only on the skin: ``finger2_uv_mm`` is NaN and
``force2`` 0 (or NaN, unknown) in the frames without it. ``labels`` stay the first finger's;
:attr:`Trial.n_contacts` counts the fingers on the skin per frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array, check_option
from ectskin.layout import SensorLayout
from ectskin.layout.layout import SURFACES

#: The per-frame finger ground truth of a :class:`Trial` (each optional, all three needed).
GROUND_TRUTH_FIELDS = ("contact", "finger_uv_mm", "finger_height_mm")
#: The per-frame ground truth of a second finger (all three or none).
SECOND_FINGER_FIELDS = ("contact2", "finger2_uv_mm", "force2")


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


def _bool_frames(name: str, value: Any, n: int, src: str) -> np.ndarray:
    """(n,) bool from bools or the numbers 0/1; anything else is refused, naming the frame."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{src}: {name} must be bool; {exc}") from None
    if arr.dtype != np.bool_:
        if arr.dtype.kind not in "iuf":
            raise EctskinError(f"{src}: {name} must be bool, found dtype {arr.dtype}")
        bad = ~np.isin(arr, (0, 1))
        if bad.any():
            k = tuple(int(i) for i in np.argwhere(bad)[0])
            raise EctskinError(f"{src}: {name} must be bool (or 0/1), found {arr[k]} at index {k}")
    return check_array(name, arr, (n,), dtype=np.bool_, source=src)


def check_ground_truth(
    src: str, n: int, contact: Any, finger_uv_mm: Any, finger_height_mm: Any
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """Checked finger ground truth of ``n`` frames (each argument may be None = not recorded).

    ``contact`` (n,) bool; ``finger_uv_mm`` (n, 2) float64, a row all NaN or all finite;
    ``finger_height_mm`` (n,) float64, NaN or >= 0. Where both positions are given they agree on
    the frames without a finger (NaN); in contact frames the point is known and the height is 0.
    Raises an :class:`EctskinError` naming ``src``, the field and the first bad frame.
    """
    if contact is not None:
        contact = _bool_frames("contact", contact, n, src)
    uv_missing = h_missing = None
    if finger_uv_mm is not None:
        finger_uv_mm = check_array("finger_uv_mm", finger_uv_mm, (n, 2), source=src)
        nan = np.isnan(finger_uv_mm)
        bad = np.isinf(finger_uv_mm).any(axis=1) | (nan[:, 0] != nan[:, 1])
        if bad.any():
            k = int(np.argmax(bad))
            raise EctskinError(
                f"{src}: finger_uv_mm[{k}] is {finger_uv_mm[k].tolist()}, expected two finite "
                "numbers (mm) or two NaN (no finger)"
            )
        uv_missing = nan[:, 0]
    if finger_height_mm is not None:
        finger_height_mm = check_array("finger_height_mm", finger_height_mm, (n,), source=src)
        h_missing = np.isnan(finger_height_mm)
        bad = ~h_missing & ~(np.isfinite(finger_height_mm) & (finger_height_mm >= 0))
        if bad.any():
            k = int(np.argmax(bad))
            raise EctskinError(
                f"{src}: finger_height_mm[{k}] is {finger_height_mm[k]}, expected a height >= 0 "
                "mm (0 in contact) or NaN (no finger)"
            )
    if uv_missing is not None and h_missing is not None and np.any(uv_missing != h_missing):
        k = int(np.argmax(uv_missing != h_missing))
        raise EctskinError(
            f"{src}: frame {k} has finger_uv_mm {finger_uv_mm[k].tolist()} but finger_height_mm "
            f"{finger_height_mm[k]}; both are NaN in the frames without a finger, else neither"
        )
    if contact is not None and uv_missing is not None and np.any(contact & uv_missing):
        k = int(np.argmax(contact & uv_missing))
        raise EctskinError(
            f"{src}: frame {k} is in contact but finger_uv_mm is NaN (no finger); in contact "
            "the point under the fingertip is known"
        )
    if contact is not None and h_missing is not None and np.any(contact & (finger_height_mm != 0)):
        k = int(np.argmax(contact & (finger_height_mm != 0)))
        raise EctskinError(
            f"{src}: frame {k} is in contact but finger_height_mm is {finger_height_mm[k]}, "
            "expected 0 (the height in contact)"
        )
    return contact, finger_uv_mm, finger_height_mm


def check_second_finger(
    src: str, n: int, contact2: Any, finger2_uv_mm: Any, force2: Any, surface: Any
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """Checked ground truth of a second finger over ``n`` frames (all None: none in the trial).

    ``contact2`` (n,) bool; ``finger2_uv_mm`` (n, 2) float64, finite in the frames with the second
    finger on the skin and NaN in the others; ``force2`` (n,) float64, >= 0 or NaN (unknown), 0 or
    NaN without the finger; ``surface`` the face it presses (given exactly when the arrays are).
    Raises an :class:`EctskinError` naming ``src``, the field and the first bad frame.
    """
    given = {
        k: v is not None for k, v in zip(SECOND_FINGER_FIELDS, (contact2, finger2_uv_mm, force2))
    }
    if not any(given.values()):
        if surface is not None:
            raise EctskinError(
                f"{src}: finger2_surface is {surface!r} but the trial has no second finger "
                f"({', '.join(SECOND_FINGER_FIELDS)} are None)"
            )
        return None, None, None
    if not all(given.values()):
        missing = [k for k, v in given.items() if not v]
        raise EctskinError(
            f"{src}: a second finger needs all of {', '.join(SECOND_FINGER_FIELDS)}; "
            f"{', '.join(missing)} missing (None)"
        )
    if surface is None:
        raise EctskinError(f"{src}: finger2_surface is None; a second finger needs its face")
    contact2 = _bool_frames("contact2", contact2, n, src)
    finger2_uv_mm = check_array("finger2_uv_mm", finger2_uv_mm, (n, 2), source=src)
    force2 = check_array("force2", force2, (n,), source=src)
    finite = np.isfinite(finger2_uv_mm).all(axis=1)
    nan = np.isnan(finger2_uv_mm).all(axis=1)
    bad = np.where(contact2, ~finite, ~nan)
    if bad.any():
        k = int(np.argmax(bad))
        want = "two finite numbers (mm)" if contact2[k] else "two NaN (no second finger)"
        raise EctskinError(
            f"{src}: finger2_uv_mm[{k}] is {finger2_uv_mm[k].tolist()} with contact2 "
            f"{bool(contact2[k])}, expected {want}"
        )
    known = ~np.isnan(force2)
    bad = known & ~(np.isfinite(force2) & (force2 >= 0) & (contact2 | (force2 == 0)))
    if bad.any():
        k = int(np.argmax(bad))
        want = "a force >= 0 N or NaN" if contact2[k] else "0 or NaN (no second finger)"
        raise EctskinError(
            f"{src}: force2[{k}] is {force2[k]} with contact2 {bool(contact2[k])}, expected {want}"
        )
    return contact2, finger2_uv_mm, force2


@dataclass
class Trial:
    """One trial of frames with its labels; validated on construction."""

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
    finger_surface: str | None = None
    contact2: np.ndarray | None = None
    finger2_uv_mm: np.ndarray | None = None
    force2: np.ndarray | None = None
    finger2_surface: str | None = None
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
        if self.force is not None:
            self.force = check_array("force", self.force, (n,), source=src)
        self.contact, self.finger_uv_mm, self.finger_height_mm = check_ground_truth(
            src, n, self.contact, self.finger_uv_mm, self.finger_height_mm
        )
        if self.finger_surface is not None:
            check_option("finger_surface", self.finger_surface, SURFACES, source=src)
        self.contact2, self.finger2_uv_mm, self.force2 = check_second_finger(
            src, n, self.contact2, self.finger2_uv_mm, self.force2, self.finger2_surface
        )
        if self.finger2_surface is not None:
            check_option("finger2_surface", self.finger2_surface, SURFACES, source=src)
        self.inflation = tuple(float(v) for v in self.inflation)
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
    def has_occlusion(self) -> bool:
        return self.markers is not None and bool(np.isnan(self.markers).any())

    @property
    def has_second_finger(self) -> bool:
        """True when the trial carries a second finger's ground truth."""
        return self.contact2 is not None

    @property
    def n_contacts(self) -> np.ndarray | None:
        """(n_frames,) int: fingers on the skin per frame (0, 1 or 2); None without ``contact``."""
        if self.contact is None:
            return None
        n = self.contact.astype(np.int64)
        return n + self.contact2 if self.contact2 is not None else n

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
