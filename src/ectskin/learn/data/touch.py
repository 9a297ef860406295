"""Touch-recognition samples from a recording: :func:`touch_dataset` → :class:`TouchData`.

One sample per frame: the frame's calibrated readouts (paper Eq. 2, see
:mod:`ectskin.io.calibration`) and its touch class (0 = no touch, 1..n_regions).

The reference c_0 of Eq. 2 is the rest state by default (the paper's); ``"state"`` and
``"inflation"`` calibrate each trial against the rest readout at its own inflation
(:mod:`ectskin.io.inflation_reference`). The data set records which in ``reference``
(:func:`reference_doc`): a trained run stores it (``split.json`` ``touch_reference``, and the
checkpoint's ``extra``), and :func:`stored_touch_reference` gives it back to evaluation, so the
run's frames are calibrated the same way on any recording.

Channels a recording does not measure (``rec.meta["unmeasured_pairs"]``, set by the generic
importer, see ``docs/import-format.md``) are left out: ``pair_names`` lists the measured channels
only (the file's own channel names when the import stored them in ``rec.meta["channel_names"]``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.calibration import (
    ReferenceChoice,
    calibrate,
    is_difference,
    own_reference,
    reference_divisor,
    touch_reference,
)
from ectskin.io.inflation_reference import InflationModel
from ectskin.io.recording import Recording
from ectskin.learn.channels import channel_names, check_regions, measured_channels
from ectskin.learn.data.base import NONFINITE_OPTIONS, SampleData, finite_rows, select_trials

log = logging.getLogger(__name__)

__all__ = [
    "FOLLOWS_INFLATION",
    "TouchData",
    "reference_doc",
    "stored_touch_reference",
    "touch_dataset",
]

#: the reference modes that follow the inflation (stored in a run, re-applied by evaluation)
FOLLOWS_INFLATION = ("state", "inflation", "state-offset", "inflation-offset")


@dataclass
class TouchData(SampleData):
    """Touch-recognition samples, one per frame.

    Attributes
    ----------
    x : (n, n_pairs) float32
        Calibrated readouts (Eq. 2), dimensionless.
    y : (n,) int64
        Touch class, 0 = no touch, 1..n_regions.
    group : (n,) int64
        Index into ``group_names`` of the sample's trial (for trial-exclusive splits).
    group_names : list of str
        Trial names.
    n_classes : int
        1 + number of regions of the layout.
    pair_names : list of str
        Channel names (measured pairs), length n_pairs.
    group_region : (n_groups,) int64
        Each trial's touched region (0 = none): the ``stratify`` labels of
        :func:`~ectskin.learn.splits.split_groups`.
    reference : dict
        The Eq. 2 reference the frames were calibrated with (:func:`reference_doc`, plain JSON):
        ``{"mode": "rest" | "meta" | "array" | "difference" | "state" | "inflation"}``, with
        ``"model"`` (:meth:`InflationModel.to_json`) for "inflation"; empty when not known.
    """

    SAMPLE_FIELDS: ClassVar[tuple[str, ...]] = ("x", "y", "group")
    MATCH_FIELDS: ClassVar[tuple[str, ...]] = ("pair_names", "n_classes")

    x: np.ndarray
    y: np.ndarray
    group: np.ndarray
    group_names: list[str]
    n_classes: int
    pair_names: list[str]
    group_region: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    reference: dict[str, Any] = field(default_factory=dict)

    @property
    def n_pairs(self) -> int:
        return int(self.x.shape[1])


def touch_dataset(
    rec: Recording,
    *,
    reference: str | np.ndarray | InflationModel = "auto",
    trials: Sequence[str | int] | None = None,
    nonfinite: str = "raise",
) -> TouchData:
    """Calibrated touch frames of a recording, one sample per frame.

    Parameters
    ----------
    rec : Recording
    reference : "auto" | "rest" | "meta" | "state" | "inflation" | InflationModel | array
        The reference c_0 of Eq. 2 (see :func:`ectskin.io.calibration.touch_reference`);
        "auto" = the mean readout of the uninflated, untouched trial (or per-trial references of
        a generic import); "state" = that of each trial's own inflation state; "inflation" =
        an :class:`InflationModel` fitted on the recording's states (a model given: applied).
    trials : sequence of names or indices, optional
        Restrict to these trials (default: all, in recording order).
    nonfinite : "raise" | "drop"
        A frame with a non-finite readout (masked channel) is an error naming the trial, frame and
        channel ("raise"), or is left out with a logged count ("drop").

    Returns
    -------
    TouchData with ``group`` indexing the selected trials in order, and ``reference`` saying
    which reference calibrated it.
    """
    if nonfinite not in NONFINITE_OPTIONS:
        raise EctskinError(
            f"Invalid value for 'nonfinite': allowed values are 'raise', 'drop'; got {nonfinite!r}"
        )
    keep = measured_channels(rec)
    pair_names = channel_names(rec, keep)
    if isinstance(reference, str) and reference.startswith("inflation") and not is_difference(rec):
        over = "own" if reference == "inflation" else "rest"
        reference = InflationModel.fit(rec, keep, divisor=over)
    refs = touch_reference(rec, reference=reference, channels=keep)
    divisor = reference_divisor(rec, reference, keep)  # None: Eq. 2 divides by c_0 itself
    chosen = select_trials(rec, trials)
    if not chosen:
        raise EctskinError("touch_dataset: no trials selected")
    check_regions(rec, chosen)
    xs, ys, gs = [], [], []
    dropped = 0
    for g, t in enumerate(chosen):
        c = calibrate(
            t.capacitance[:, keep],
            refs[t.name],
            source=f"trial {t.name!r}",
            pair_names=pair_names,
            allow_nonfinite=nonfinite == "drop",
        )
        if divisor is not None:  # (c_t - c_0(p)) / c_0(0) = Eq. 2 x c_0(p) / c_0(0)
            c = (c * (refs[t.name] / divisor)).astype(np.float32)
        ok = finite_rows(c)
        if not ok.all():
            dropped += int((~ok).sum())
            c = c[ok]
        xs.append(c)
        ys.append(t.labels[ok].astype(np.int64))
        gs.append(np.full(c.shape[0], g, dtype=np.int64))
    if dropped:
        log.warning("touch_dataset: dropped %d frames with non-finite readouts", dropped)
    return TouchData(
        x=np.concatenate(xs, axis=0),
        y=np.concatenate(ys),
        group=np.concatenate(gs),
        group_names=[t.name for t in chosen],
        n_classes=rec.layout.n_classes,
        pair_names=pair_names,
        group_region=np.array([t.region for t in chosen], dtype=np.int64),
        reference=reference_doc(rec, reference),
    )


def reference_doc(rec: Recording, reference: Any) -> dict[str, Any]:
    """What ``reference`` (as :func:`touch_dataset` takes it) calibrated ``rec`` with, as plain
    JSON: ``{"mode": ...}`` (module docstring; "auto" resolved to the recording's own)."""
    if is_difference(rec):
        return {"mode": "difference"}
    if isinstance(reference, InflationModel):
        return {"mode": reference.mode, "model": reference.to_json()}
    if not isinstance(reference, str):
        return {"mode": "array"}
    if reference == "auto":
        return {"mode": own_reference(rec) or "rest"}
    return {"mode": reference}


def stored_touch_reference(
    split: dict[str, Any], extra: dict[str, Any], source: str
) -> ReferenceChoice | None:
    """The reference a trained touch run calibrates with when it follows the inflation
    (:data:`FOLLOWS_INFLATION`): from ``split.json``'s ``touch_reference``, else the checkpoint's
    ``extra["reference"]``; as a :class:`ReferenceChoice` whose ``value`` is "state" or the
    stored :class:`InflationModel`. None for a run calibrated against the rest state (or
    trained before runs stored their reference): evaluation then chooses as before."""
    doc = split.get("touch_reference") or extra.get("reference") or {}
    if not isinstance(doc, dict):
        raise EctskinError(f"{source}: 'touch_reference' must be an object, got {doc!r:.60}")
    mode = doc.get("mode")
    if mode not in FOLLOWS_INFLATION:
        return None
    if mode in ("state", "state-offset"):
        text = (
            "each trial's own inflation state: the mean of its no-contact trial(s) (the run's "
            f"reference {mode!r})"
        )
        return ReferenceChoice(mode, "run", text)
    model = InflationModel.from_json(doc.get("model") or {}, f"{source}: touch_reference model")
    text = (
        f"the rest readout predicted at each trial's inflation by the run's inflation model "
        f"(degree {model.degree}, fitted on {len(model.states)} states of the training recording; "
        f"reference {model.mode!r})"
    )
    return ReferenceChoice(model, "run", text)
