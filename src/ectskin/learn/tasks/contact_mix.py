"""The finger mix of the contact training: a window with one finger on the skin takes another
finger's signal, taken from the training split (:func:`finger_signals`, :func:`mix_fingers`).

Half the windows picked take the signal of a finger *above* the skin (at most
:data:`MIX_HOVER_MAX_MM` high; the labels stay: that finger is not on it), the other half
(:data:`MIX_TOUCH_SHARE`) that of a finger *on* the skin elsewhere (the labels gain it as the
second finger, count 2; a finger within :data:`MIX_APART_MM` of the first on the same face is
not added). A signal is a window less the window of its trial's first frame, when no finger is
within :data:`MIX_FAR_MM` of the skin there (the twin's fingers come down from 100 mm); the
hand's push differs between the two frames and stays in the signal as noise.

Why: a finger hovering a few millimetres above the skin while another touches adds a signal of
the order of a touch's, and such frames (the twin's second finger pressing while the first is
lifted) are few in the data, at one point per trial; a model trained on them alone tends to put
such a touch at the hovering finger. Mixing hovering fingers alone would teach that two finger
signals are always one finger; mixing touching fingers too keeps the count honest. Signals add
as the twin's field reading adds a second finger's; on a real skin two fingers also screen each
other a little (docs/contact.md), which the mix neglects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ectskin.learn.data.contact import ContactData

#: the highest finger (mm above the skin) whose signal is mixed in as a hovering finger
MIX_HOVER_MAX_MM = 30.0
#: a trial's first frame is its window without a finger when no finger is this close (mm)
MIX_FAR_MM = 60.0
#: at most this many signals of each kind (a seeded subsample)
MIX_SIGNALS_MAX = 20000
#: the share of the mixed windows that take a touching finger (the rest a hovering one)
MIX_TOUCH_SHARE = 0.5
#: a touching finger is not added within this distance (mm) of the first on its face
MIX_APART_MM = 20.0


@dataclass
class FingerSignals:
    """What :func:`finger_signals` takes from a training split: ``hover`` (m, k, P) signals of a
    finger above the skin; ``touch`` (t, k, P) of a finger on it, with its ``face`` (t,),
    ``uv`` (t, 2) mm and ``force`` (t,) N. Tensors (float32; face int64)."""

    hover: torch.Tensor
    touch: torch.Tensor
    face: torch.Tensor
    uv: torch.Tensor
    force: torch.Tensor

    def __len__(self) -> int:
        return min(len(self.hover), len(self.touch))

    def to(self, device) -> FingerSignals:
        return FingerSignals(*(getattr(self, f).to(device) for f in self.__dataclass_fields__))


def finger_signals(
    data: ContactData,
    *,
    hover_max_mm: float = MIX_HOVER_MAX_MM,
    far_mm: float = MIX_FAR_MM,
    max_signals: int = MIX_SIGNALS_MAX,
    seed: int = 0,
) -> FingerSignals:
    """The signals of the fingers of ``data`` (module docstring): every window with no finger on
    the skin and one at most ``hover_max_mm`` above it (hover), and every window with one finger
    on it (touch), each less its trial's first window when no finger is within ``far_mm`` of the
    skin there (other trials, and those whose first frame is not in ``data``, give none)."""
    first: dict[int, int] = {}
    for row in np.flatnonzero(data.frame == 0):
        if data.count[row] == 0 and not data.height[row] < far_mm:  # NaN (no finger) or far
            first[int(data.group[row])] = int(row)
    known = np.isin(data.group, np.fromiter(first, np.int64, len(first)))
    rng = np.random.default_rng(seed)
    parts = []
    for mask in (
        (data.count == 0) & (data.height <= hover_max_mm) & known,
        (data.count == 1) & known,
    ):
        rows = np.flatnonzero(mask)
        if rows.size > max_signals:
            rows = rng.choice(rows, max_signals, replace=False)
        base = np.array([first[int(g)] for g in data.group[rows]], dtype=np.int64)
        parts.append((torch.from_numpy((data.x[rows] - data.x[base]).astype(np.float32)), rows))
    (hover, _), (touch, rows) = parts
    return FingerSignals(
        hover=hover,
        touch=touch,
        face=torch.from_numpy(data.face[rows, 0].astype(np.int64)),
        uv=torch.from_numpy(data.uv[rows, 0].astype(np.float32)),
        force=torch.from_numpy(data.force[rows, 0].astype(np.float32)),
    )


def mix_fingers(batch: tuple, signals: FingerSignals, p: float, rng: np.random.Generator) -> tuple:
    """``batch`` (x, count, face, uv, force, hover) with each window of one finger on the skin
    taking, with probability ``p``, a signal of ``signals`` (module docstring). Random numbers
    drawn, in order: the windows picked, touch or hover, the hover signal, the touch signal."""
    x, count, face, uv, force, hover = batch
    n, dev = len(x), x.device
    pick = torch.from_numpy(rng.random(n) < p).to(dev) & (count == 1)
    as_touch = torch.from_numpy(rng.random(n) < MIX_TOUCH_SHARE).to(dev)
    jh = torch.from_numpy(rng.integers(0, len(signals.hover), n)).to(dev)
    jt = torch.from_numpy(rng.integers(0, len(signals.touch), n)).to(dev)
    t_face, t_uv = signals.face[jt], signals.uv[jt]
    apart = (t_face != face[:, 0]) | ((t_uv - uv[:, 0]).norm(dim=-1) >= MIX_APART_MM)
    h, t = pick & ~as_touch, pick & as_touch & apart
    x = x + h.to(x.dtype)[:, None, None] * signals.hover[jh]
    x = x + t.to(x.dtype)[:, None, None] * signals.touch[jt]
    face, uv, force = face.clone(), uv.clone(), force.clone()
    face[t, 1], uv[t, 1], force[t, 1] = t_face[t], t_uv[t], signals.force[jt][t]
    return x, torch.where(t, 2, count), face, uv, force, hover
