"""Contact samples from recordings with per-frame finger ground truth: :class:`ContactData`.

One sample per frame: the window of the last ``k`` calibrated frames (paper Eq. 2 against the
touch reference, as for touch classification; the first frames of a trial are padded with
copies of its frame 0) and what the fingers do at the window's last frame:

================  ================  ========================================================
``count``         (n,) int64        fingers on the skin: 0, 1 or 2
``face``          (n, S) int64      index into ``faces`` of each finger's face, −1 = no finger
``uv``            (n, S, 2) float   each finger's point on its face (u, v) = (x, z) in mm
``force``         (n, S) float      each finger's normal force in N (0 without a finger)
``hover``         (n,) float        1 when no finger is on the skin and one is above it at a
                                    height of at most ``hover_max_mm``, else 0
``height``        (n,) float        the lowest finger's height above the skin in mm, NaN
                                    without a finger (0 in contact)
``other_height``  (n,) float        the lowest height above the skin (mm) of the fingers that
                                    are over it but not on it, NaN where there is none (every
                                    finger of the frame on the skin, or away): with one finger
                                    on the skin, where the hand's other finger is
================  ================  ========================================================

S = :data:`MAX_FINGERS` slots, filled from the trial's fingers axis
(:class:`~ectskin.io.recording.Trial`): the fingers on the skin in a frame take the slots in the
order of the axis (with one finger on the skin it is slot 0; the loss and the metrics match two
in either order, see :mod:`ectskin.learn.tasks.contact`). A frame with more than S fingers on
the skin is an error naming the trial.

Labels come from the twin (``ectskin simulate``) or from an import with contact labels
(``docs/import-format.md``); a recording without them is one clear error
(:func:`ectskin.io.require_ground_truth`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ectskin._check import EctskinError
from ectskin.io import Recording, require_ground_truth
from ectskin.io.calibration import calibrate, touch_reference
from ectskin.io.generic import is_virtual_layout
from ectskin.io.recording import Trial
from ectskin.learn.channels import channel_names, measured_channels
from ectskin.learn.data.base import SampleData
from ectskin.twin.mechanics import recording_manipulator

log = logging.getLogger(__name__)

#: finger slots of a contact sample
MAX_FINGERS = 2
#: a finger this high above the skin or lower (and not on it) is "hovering" (mm; the twin's
#: ``Protocol.hover_max_mm``)
HOVER_MAX_MM = 15.0
#: the contact task's trial split (train, val, test), as fractions scaled by split_groups
CONTACT_SPLIT = (0.66, 0.17, 0.17)


@dataclass
class ContactData(SampleData):
    """Contact samples, one per frame (see the module docstring for the targets).

    ``x`` (n, k, n_pairs) float32: the calibrated window, oldest frame first; ``group`` (n,)
    index into ``group_names``; ``frame`` (n,) the frame inside its trial; ``state`` (n,) index
    into ``states`` (the trial's inflation); ``faces`` the face names of ``face``;
    ``face_extent`` {face: ((u_lo, u_hi), (v_lo, v_hi))} mm, the skins' extents (scales the
    position targets); ``group_region`` (n_groups,) each trial's region (stratification);
    ``region_centre`` (n_regions + 1, 3) each region's (face index, u, v) (row 0: no region).
    ``body_mm`` (width, thickness) of the body the recording was made on (its
    ``meta["manipulator"]``, else the default body; ``body_source`` says which): the distance
    from one face to the other over the skin goes around it. ``regions_physical``: False when
    the layout's regions are no touch regions of a skin (none, or the virtual layout of a
    generic import, :func:`ectskin.io.generic.is_virtual_layout`).
    """

    SAMPLE_FIELDS: ClassVar[tuple[str, ...]] = (
        "x",
        "count",
        "face",
        "uv",
        "force",
        "hover",
        "height",
        "other_height",
        "group",
        "frame",
        "state",
    )
    MATCH_FIELDS: ClassVar[tuple[str, ...]] = ("pair_names", "states")

    x: np.ndarray
    count: np.ndarray
    face: np.ndarray
    uv: np.ndarray
    force: np.ndarray
    hover: np.ndarray
    height: np.ndarray
    other_height: np.ndarray
    group: np.ndarray
    frame: np.ndarray
    state: np.ndarray
    group_names: list[str]
    pair_names: list[str]
    faces: list[str]
    states: list[tuple[float, ...]]
    face_extent: dict[str, tuple[tuple[float, float], tuple[float, float]]]
    body_mm: tuple[float, float]
    body_source: str
    group_region: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    region_centre: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    regions_physical: bool = True

    @property
    def window(self) -> int:
        return int(self.x.shape[1])

    def aligned_to(self, other: ContactData) -> ContactData:
        """These samples with their ``state`` indices into ``other.states`` (a recording of some
        of ``other``'s inflation states joins its training split, :mod:`ectskin.learn.
        extra_train`); a state ``other`` lacks is refused, naming it."""
        if self.states == other.states:
            return self
        missing = [s for s in self.states if s not in other.states]
        if missing:
            raise EctskinError(
                f"inflation state(s) {[list(s) for s in missing]} ml are not among the run's "
                f"states {[list(s) for s in other.states]}: the contact model knows only those"
            )
        index = np.array([other.states.index(s) for s in self.states], dtype=np.int64)
        return replace(self, state=index[self.state], states=list(other.states))

    @property
    def n_pairs(self) -> int:
        return int(self.x.shape[2])


def _fingers(t: Trial, faces: list[str]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, int]]:
    """Per finger of trial ``t`` that touches the skin: (on (n,), uv (n, 2), force (n,), face
    index), in the order of the fingers axis."""
    out = []
    for k in range(t.n_fingers):
        f = t.finger(k)
        if f.contact is None or f.uv_mm is None or not f.contact.any():
            continue
        if f.surface not in faces:
            raise EctskinError(
                f"trial {t.name!r}: finger {k} touches surface {f.surface!r}, which holds no skin "
                f"of the layout (skins on {', '.join(faces)})"
            )
        force = np.zeros(t.n_frames) if f.force is None else np.where(f.contact, f.force, 0.0)
        out.append((f.contact, f.uv_mm, force, faces.index(f.surface)))
    return out


def other_finger_height(t: Trial) -> np.ndarray:
    """(n_frames,) the lowest height above the skin (mm) of ``t``'s fingers that are over it but
    not on it, NaN where there is none (every finger on the skin, or away, or no heights)."""
    if t.finger_height_mm is None or not t.n_fingers:
        return np.full(t.n_frames, np.nan)
    on_skin = t.finger_height_mm == 0 if t.contact is None else t.contact
    return np.fmin.reduce(np.where(on_skin, np.nan, t.finger_height_mm), axis=1)


def contact_dataset(
    rec: Recording,
    *,
    window: int = 5,
    reference: str | np.ndarray = "auto",
    hover_max_mm: float = HOVER_MAX_MM,
    trials: Sequence[str] | None = None,
) -> ContactData:
    """The contact samples of ``rec`` (every frame of every trial, or of ``trials``).

    ``window``: frames per sample (1 = the frame alone); ``reference``: the touch reference of
    Eq. 2 (:func:`ectskin.io.calibration.touch_reference`). Frames with a non-finite readout are
    an error naming the trial, frame and channel (as for touch).
    """
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
        raise EctskinError(f"contact window must be an integer >= 1, got {window!r}")
    if not (np.isfinite(hover_max_mm) and hover_max_mm > 0):
        raise EctskinError(f"hover_max_mm must be a finite number > 0, got {hover_max_mm!r}")
    require_ground_truth(rec)
    keep = measured_channels(rec)
    pair_names = channel_names(rec, keep)
    refs = touch_reference(rec, reference=reference, channels=keep)
    chosen = list(rec.trials) if trials is None else [rec.trial(n) for n in trials]
    if not chosen:
        raise EctskinError("contact_dataset: no trials selected")
    faces = [s.surface for s in rec.layout.skins]
    faces = list(dict.fromkeys(faces))
    extent: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {}
    for s in rec.layout.skins:
        lo_u, hi_u = extent.get(s.surface, ((np.inf, -np.inf), (0, 0)))[0]
        lo_v, hi_v = extent.get(s.surface, ((0, 0), (np.inf, -np.inf)))[1]
        extent[s.surface] = (
            (float(min(lo_u, s.u_mm[0])), float(max(hi_u, s.u_mm[1]))),
            (float(min(lo_v, s.v_mm[0])), float(max(hi_v, s.v_mm[1]))),
        )
    region_centre = np.zeros((rec.layout.n_regions + 1, 3))
    for r in rec.layout.regions:
        region_centre[r.id] = (faces.index(r.surface) if r.surface in faces else -1, *r.centre_mm)
    states = list(dict.fromkeys(t.inflation for t in chosen))
    cols: dict[str, list[np.ndarray]] = {
        k: []
        for k in ContactData.SAMPLE_FIELDS
    }
    for g, t in enumerate(chosen):
        n = t.n_frames
        if n == 0:
            continue
        c = calibrate(
            t.capacitance[:, keep], refs[t.name], source=f"trial {t.name!r}", pair_names=pair_names
        ).astype(np.float32)
        padded = np.concatenate([np.repeat(c[:1], window - 1, axis=0), c], axis=0)
        x = sliding_window_view(padded, window, axis=0).transpose(0, 2, 1)  # (n, k, P)
        count = np.zeros(n, np.int64)
        face = np.full((n, MAX_FINGERS), -1, np.int64)
        uv = np.zeros((n, MAX_FINGERS, 2))
        force = np.zeros((n, MAX_FINGERS))
        for on, f_uv, f_force, f_face in _fingers(t, faces):
            slot = count[on]
            if np.any(slot >= MAX_FINGERS):
                raise EctskinError(f"trial {t.name!r}: more than {MAX_FINGERS} fingers at once")
            rows = np.flatnonzero(on)
            face[rows, slot] = f_face
            uv[rows, slot] = f_uv[on]
            force[rows, slot] = f_force[on]
            count[on] += 1
        if not np.all(np.isfinite(uv)):
            i = int(np.argmax(~np.isfinite(uv).all(axis=(1, 2))))
            raise EctskinError(
                f"trial {t.name!r}: frame {i} is in contact but its finger position is not finite"
            )
        # the lowest finger's height (NaN where every finger is away)
        height = np.full(n, np.nan)
        if t.finger_height_mm is not None and t.n_fingers:
            height = np.fmin.reduce(t.finger_height_mm, axis=1)
        other = other_finger_height(t)
        hover = (count == 0) & np.isfinite(height) & (height <= hover_max_mm)
        cols["x"].append(np.ascontiguousarray(x))
        cols["count"].append(count)
        cols["face"].append(face)
        cols["uv"].append(uv.astype(np.float32))
        cols["force"].append(force.astype(np.float32))
        cols["hover"].append(hover.astype(np.float32))
        cols["height"].append(np.where(count > 0, 0.0, height).astype(np.float32))
        cols["other_height"].append(other.astype(np.float32))
        cols["group"].append(np.full(n, g, np.int64))
        cols["frame"].append(np.arange(n, dtype=np.int64))
        cols["state"].append(np.full(n, states.index(t.inflation), np.int64))
    if not cols["x"]:
        raise EctskinError("contact_dataset: the selected trials hold no frames")
    body, body_source = recording_manipulator(rec.meta)
    if body_source == "default":
        log.info(
            "the recording names no manipulator: distances between faces go around the default "
            "body (%g x %g mm)", body.width_mm, body.thickness_mm
        )
    arrays = {k: np.concatenate(v, axis=0) for k, v in cols.items()}
    return ContactData(
        **arrays,
        group_names=[t.name for t in chosen],
        pair_names=list(pair_names),
        faces=faces,
        states=states,
        face_extent=extent,
        group_region=np.array([t.region for t in chosen], dtype=np.int64),
        region_centre=region_centre,
        regions_physical=bool(rec.layout.n_regions) and not is_virtual_layout(rec),
        body_mm=(float(body.width_mm), float(body.thickness_mm)),
        body_source=body_source,
    )
