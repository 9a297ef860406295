"""Checks of the frames handed to :meth:`RecordingWriter.append
<ectskin.io.hdf5.append.RecordingWriter.append>`: shapes, units, one frame or many, broadcast
scalars, labels within the layout, increasing timestamps and the fingers (with the policy of
:func:`ectskin.io.recording.check_fingers`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array
from ectskin.io.recording import FINGER_FRAME_FIELDS, check_fingers
from ectskin.layout import SensorLayout


def _frames_arg(
    name: str,
    value: Any,
    tail: tuple[int, ...],
    n: int | None,
    src: str,
    *,
    finite: bool = False,
    broadcast: bool = False,
) -> np.ndarray:
    """``value`` as a float64 array (n, *tail); an array of shape ``tail`` is one frame.

    With ``broadcast`` a scalar is repeated for all ``n`` frames.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{src}: {name} must be numeric; {exc}") from None
    if broadcast and arr.ndim == 0 and n is not None:
        arr = np.full(n, arr)
    elif arr.shape == tail:
        arr = arr[None]
    return check_array(name, arr, (n, *tail), finite=finite, source=src)


def check_frames(
    layout: SensorLayout,
    src: str,
    last_t: float,
    capacitance: Any,
    timestamps: Any,
    labels: Any,
    optional: dict[str, Any],
    trial_fingers: dict[str, Any],
) -> dict[str, Any]:
    """The arguments of ``RecordingWriter.append`` as checked arrays by ``/frames`` dataset.

    ``optional`` maps each of :data:`~ectskin.io.hdf5.schema.OPTIONAL_FRAMES` to its argument
    (None = not given, returned as None); the finger fields come back on the fingers axis
    (n, n_fingers, ...), with ``n_fingers``. A scalar ``force``, ``contact`` or
    ``finger_height_mm`` is one finger in every frame, a ``finger_uv_mm`` of shape (2,) one
    finger in one frame. ``trial_fingers``: the trial's ``finger_surface``,
    ``finger_radius_mm`` and ``finger_modulus_mpa`` as given to ``start_trial`` (None = not
    given), which the arrays must agree with. ``last_t``: the trial's last timestamp so far, s
    (-inf before its first frame). Errors name ``src``.
    """
    L = layout
    cap = _frames_arg("capacitance", capacitance, (L.n_pairs,), None, src)
    n = cap.shape[0]
    ts = _frames_arg("timestamps", timestamps, (), n, src, finite=True)
    if labels is None:
        lab = np.zeros(n, dtype=np.int16)
    else:
        lab = _frames_arg("labels", labels, (), n, src, finite=True, broadcast=True)
        bad = (lab != np.round(lab)) | (lab < 0) | (lab > L.n_regions)
        if bad.any():
            k = int(np.argmax(bad))
            raise EctskinError(
                f"{src}: labels[{k}] is {lab[k]}, expected an integer 0..{L.n_regions}"
            )
        lab = lab.astype(np.int16)
    out: dict[str, Any] = {"capacitance": cap, "timestamps": ts, "labels": lab}
    markers = optional["markers"]
    out["markers"] = (
        None if markers is None else _frames_arg("markers", markers, (L.n_markers, 3), n, src)
    )
    fingers = {}
    for key in FINGER_FRAME_FIELDS:
        value = optional[key]
        if value is not None and np.ndim(value) == 0:  # one finger, every frame
            value = np.full(n, value)
        elif key == "finger_uv_mm" and value is not None and np.shape(value) == (2,):
            value = np.asarray(value)[None]  # one finger, one frame
        fingers[key] = value
    out.update(check_fingers(src, n, **fingers, **trial_fingers))
    prev = np.concatenate([[last_t], ts])
    if n and np.any(np.diff(prev) <= 0):
        k = int(np.argmax(np.diff(prev) <= 0))
        raise EctskinError(
            f"{src}: timestamps must increase within a trial; timestamps[{k}] = {ts[k]} "
            f"comes after {prev[k]}"
        )
    return out
