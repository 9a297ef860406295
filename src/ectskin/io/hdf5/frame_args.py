"""Checks of the frames handed to :meth:`RecordingWriter.append
<ectskin.io.hdf5.append.RecordingWriter.append>`: shapes, units, one frame or many, broadcast
scalars, labels within the layout, increasing timestamps and the finger ground truth (with the
policy of :func:`ectskin.io.recording.check_ground_truth`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_array
from ectskin.io.recording import check_ground_truth, check_second_finger
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
    finger2_surface: str | None = None,
) -> dict[str, np.ndarray | None]:
    """The arguments of ``RecordingWriter.append`` as checked arrays by ``/frames`` dataset.

    ``optional`` maps each of :data:`~ectskin.io.hdf5.schema.OPTIONAL_FRAMES` to its argument
    (None = not given, returned as None). ``last_t``: the trial's last timestamp so far, s
    (-inf before its first frame). ``finger2_surface``: the trial's second finger's face (None:
    no second finger), checked with the second finger's arrays. Errors name ``src``.
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
    out = {"capacitance": cap, "timestamps": ts, "labels": lab}
    tails = {
        "markers": (L.n_markers, 3),
        "force": (),
        "finger_uv_mm": (2,),
        "finger_height_mm": (),
        "finger2_uv_mm": (2,),
        "force2": (),
    }
    for key, tail in tails.items():  # (n, *tail), one frame, or a scalar for all (tail ())
        value = optional[key]
        out[key] = (
            None if value is None else _frames_arg(key, value, tail, n, src, broadcast=not tail)
        )
    contact = optional["contact"]
    if contact is not None and np.ndim(contact) == 0:
        contact = np.full(n, contact)
    out["contact"], out["finger_uv_mm"], out["finger_height_mm"] = check_ground_truth(
        src, n, contact, out["finger_uv_mm"], out["finger_height_mm"]
    )
    contact2 = optional["contact2"]
    if contact2 is not None and np.ndim(contact2) == 0:
        contact2 = np.full(n, contact2)
    out["contact2"], out["finger2_uv_mm"], out["force2"] = check_second_finger(
        src, n, contact2, out["finger2_uv_mm"], out["force2"], finger2_surface
    )
    prev = np.concatenate([[last_t], ts])
    if n and np.any(np.diff(prev) <= 0):
        k = int(np.argmax(np.diff(prev) <= 0))
        raise EctskinError(
            f"{src}: timestamps must increase within a trial; timestamps[{k}] = {ts[k]} "
            f"comes after {prev[k]}"
        )
    return out
