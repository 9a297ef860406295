"""What the live engine emits per processed frame, its JSON message (the dashboard protocol) and
the writers of outputs.

The message carries every number of an :class:`Output` as it is (non-finite → ``null``), except
the ECT image, which is quantised (:meth:`EctFrame.to_json_dict`): it is a picture for the page,
and at full precision it would be most of every message. :class:`JsonLinesWriter` writes each
message as one line (``ectskin live --jsonl``); :func:`status_line` says one output in one line
of text (the command's status line).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ectskin._check import EctskinError
from ectskin._files import to_jsonable

#: Quantisation levels of the ECT image in a JSON message: values are sent as integers in
#: [-ECT_LEVELS, ECT_LEVELS] times ``scale / ECT_LEVELS`` (0.1 % of the largest magnitude).
ECT_LEVELS = 1000


def json_list(a: np.ndarray | None) -> list | None:
    """Array → nested lists of floats, non-finite → None (``ectskin._files``'s JSON policy)."""
    if a is None:
        return None
    a = np.asarray(a, dtype=np.float64)
    return a.tolist() if np.isfinite(a).all() else to_jsonable(a)


def quantise(images: dict[str, np.ndarray]) -> dict[str, Any]:
    """Per-face images → ``{"scale": s, "levels": L, "faces": {face: nested int lists}}`` with
    value ≈ q · s / L, s the largest finite magnitude over all faces (1.0 when all are zero);
    a non-finite pixel is ``null``. The error per pixel is at most s / (2 L)."""
    finite = [np.abs(a[np.isfinite(a)]) for a in images.values()]
    top = max((float(a.max()) for a in finite if a.size), default=0.0)
    scale = top if top > 0 else 1.0
    faces: dict[str, Any] = {}
    for face, a in images.items():
        q = np.rint(np.asarray(a, dtype=np.float64) * (ECT_LEVELS / scale))
        ok = np.isfinite(q)
        if ok.all():
            faces[face] = q.astype(np.int64).tolist()
        else:
            obj = q.astype(object)
            obj[ok] = q[ok].astype(np.int64)
            obj[~ok] = None
            faces[face] = obj.tolist()
    return {"scale": scale, "levels": ECT_LEVELS, "faces": faces}


@dataclass
class EctFrame:
    """The ECT head's result for one frame: ``images`` per face (n_v, n_u), row 0 at the lowest
    v, column 0 at the lowest u, over the imager's ``grid_extent``; the located touch ``face``,
    ``u_mm``, ``v_mm`` and the image value there, ``peak``."""

    images: dict[str, np.ndarray]
    face: str
    u_mm: float
    v_mm: float
    peak: float

    def to_json_dict(self) -> dict[str, Any]:
        """``{"face", "u_mm", "v_mm", "peak", "image": quantise(images)}`` (non-finite → None)."""
        return {
            "face": self.face,
            "u_mm": _number(self.u_mm),
            "v_mm": _number(self.v_mm),
            "peak": _number(self.peak),
            "image": quantise(self.images),
        }


@dataclass
class InversionFrame:
    """The physical-inversion head's result for one frame (:mod:`ectskin.live.inversion_head`):
    the inflation ``state`` (ml) whose field it was fitted through; ``n_fingers`` (0, 1 or 2,
    chosen by BIC) and per finger its ``FingerEstimate`` (:mod:`ectskin.inversion.fit`: face,
    pressing or hovering, u, v mm, force N, height mm and their standard errors);
    ``bic_by_count`` (index = count, inf where not tried); whether the chosen fit
    ``converged``; whether it started ``warm`` from the previous frame's answer; ``fit_ms``
    the fit's wall time; ``finger``: the person's finger pooled so far, this frame included
    (``{"modulus_ln": [centre, sd], "radius_ln": [centre, sd], "frames": n}``, the nuisances
    fitted; ln of the ratio to the field's finger), None where the head pools none;
    ``model_error``: the floor the standard errors carry (``{"a_pf", "r", "frames"}``, frames:
    how many fitted frames estimated it, None for a given floor), None: the noise alone."""

    state: tuple[float, ...]
    n_fingers: int
    fingers: tuple[Any, ...]
    bic_by_count: tuple[float, ...]
    converged: bool
    warm: bool
    fit_ms: float
    finger: dict[str, Any] | None = None
    model_error: dict[str, Any] | None = None

    def to_json_dict(self) -> dict[str, Any]:
        """``{"state", "n_fingers", "fingers": [{"face", "contact", "u_mm", "v_mm", "force_n",
        "height_mm", "u_se_mm", "v_se_mm", "force_se_n", "height_se_mm"}], "bic_by_count",
        "converged", "warm", "fit_ms", "finger", "model_error"}`` (non-finite → None)."""
        return {
            "state": [float(v) for v in self.state],
            "n_fingers": int(self.n_fingers),
            "fingers": [
                {"face": str(f.face), "contact": bool(f.contact),
                 **{k: _number(getattr(f, k)) for k in FINGER_NUMBERS}}
                for f in self.fingers
            ],
            "bic_by_count": [_number(b) for b in self.bic_by_count],
            "converged": bool(self.converged),
            "warm": bool(self.warm),
            "fit_ms": _number(self.fit_ms),
            "finger": None if self.finger is None else {
                k: int(v) if k == "frames" else [_number(x) for x in v]
                for k, v in self.finger.items()},
            "model_error": None if self.model_error is None else {
                k: v if v is None or k == "frames" else _number(v)
                for k, v in self.model_error.items()},
        }


#: the numbers of one fitted finger in a message (:class:`InversionFrame`)
FINGER_NUMBERS = ("u_mm", "v_mm", "force_n", "height_mm",
                  "u_se_mm", "v_se_mm", "force_se_n", "height_se_mm")


def _number(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass
class Output:
    """What the engine emits per processed frame.

    ``raw`` (n_pairs,) pF; ``calibrated`` (n_pairs,) Eq. 2 against the touch reference (None until
    a reference exists); ``touch_probs`` (n_classes,) and ``touch_cls``; ``markers_pred``,
    ``markers_reference``, ``markers_true`` (n_markers, 3) mm; ``label``, ``trial`` and
    ``inflation`` (ml) as the frame carried them (None when the source does not know);
    ``contact`` the contact head's ``ContactReading`` (:mod:`ectskin.learn.predict.contact`),
    ``ect`` the ECT head's :class:`EctFrame` and ``inversion`` the physical-inversion head's
    :class:`InversionFrame` (None without the head, before a reference exists, and for the ECT
    and inversion heads on frames between their ``every``-th); ``latency_ms`` from the frame's arrival
    to this output; ``stats`` a snapshot of :attr:`LiveEngine.stats`.
    """

    seq: int
    t: float
    raw: np.ndarray
    calibrated: np.ndarray | None = None
    touch_probs: np.ndarray | None = None
    touch_cls: int | None = None
    markers_pred: np.ndarray | None = None
    markers_reference: np.ndarray | None = None
    markers_true: np.ndarray | None = None
    label: int | None = None
    trial: str | None = None
    inflation: tuple[float, ...] | None = None
    contact: Any = None
    ect: EctFrame | None = None
    inversion: InversionFrame | None = None
    latency_ms: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)

    def to_json_dict(self) -> dict[str, Any]:
        """The ``{"type": "frame", ...}`` message the dashboard streams (non-finite → None)."""
        touch = None
        if self.touch_probs is not None:
            touch = {"cls": self.touch_cls, "probs": json_list(self.touch_probs)}
        markers = None
        if self.markers_pred is not None or self.markers_true is not None:
            markers = {
                "pred": json_list(self.markers_pred),
                "reference": json_list(self.markers_reference),
                "true": json_list(self.markers_true),
            }
        return {
            "type": "frame",
            "seq": int(self.seq),
            "t": float(self.t),
            "raw": json_list(self.raw),
            "calibrated": json_list(self.calibrated),
            "touch": touch,
            "markers": markers,
            "contact": None if self.contact is None else to_jsonable(self.contact.to_dict()),
            "ect": None if self.ect is None else self.ect.to_json_dict(),
            "inversion": None if self.inversion is None else self.inversion.to_json_dict(),
            "label": None if self.label is None else int(self.label),
            "trial": self.trial,
            "inflation": None if self.inflation is None else [float(v) for v in self.inflation],
            "latency_ms": float(self.latency_ms),
            "stats": dict(self.stats),
        }


class JsonLinesWriter:
    """Every :class:`Output` as one JSON line, its frame message (``to_json_dict()``, strict
    JSON): ``engine.run(on_output=writer)``.

    ``target`` is a path (created; an existing file is replaced only with ``overwrite``) or an
    open text stream such as ``sys.stdout`` (written to, never closed). A write error (a full
    disk) is kept in :attr:`error`, stops the writing and calls ``on_error()`` once (e.g.
    ``engine.stop``); :meth:`close` then removes the incomplete file and raises one
    :class:`EctskinError` that says how many lines were written. ``name`` names the output in
    messages (default: the path).
    """

    def __init__(
        self,
        target: str | Path | TextIO,
        *,
        overwrite: bool = False,
        on_error: Callable[[], None] | None = None,
        name: str | None = None,
    ) -> None:
        self.on_error = on_error
        self.lines = 0
        self.error: OSError | None = None
        self.path: Path | None = None
        if isinstance(target, str | Path):
            self.path = Path(target)
            self.name = name or str(target)
            if self.path.exists() and not overwrite:
                raise EctskinError(f"{self.name} exists; refusing to replace it without overwrite")
            try:
                self.file: TextIO = open(self.path, "w", encoding="utf-8")  # noqa: SIM115 - close()
            except OSError as exc:
                raise EctskinError(f"{self.name}: cannot open ({exc.strerror})") from None
        else:
            self.file = target
            self.name = name or str(getattr(target, "name", "stream"))

    def __call__(self, out: Output) -> None:
        """Write one output (nothing after a write error)."""
        if self.error is not None:
            return
        # to_json_dict() already applies the JSON policy (non-finite -> None): dump it as is
        try:
            self.file.write(json.dumps(out.to_json_dict(), allow_nan=False) + "\n")
        except OSError as exc:
            self.error = exc
            if self.on_error is not None:
                self.on_error()
            return
        self.lines += 1

    def close(self) -> None:
        """Close the file (a stream is flushed); on a write error remove the file and raise."""
        try:
            if self.path is not None:
                self.file.close()
            else:
                self.file.flush()
        except OSError as exc:  # the last buffered lines did not fit either
            self.error = self.error or exc
        if self.error is None:
            return
        removed = ""
        if self.path is not None:
            with contextlib.suppress(OSError):
                os.remove(self.path)
                removed = "; removed the incomplete file"
        why = self.error.strerror or str(self.error)
        raise EctskinError(
            f"{self.name}: cannot write ({why}); stopped after {self.lines} lines{removed}"
        )

    def __enter__(self) -> JsonLinesWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def status_line(out: Output) -> str:
    """One line of text on an output and its ``stats``: the touch class, how far the markers
    moved from the reference (the largest, mm), the contact reading, the inversion's fingers, the
    touch reference's state, the rate, latency and counters."""
    s = out.stats
    touch = "-" if out.touch_cls is None else f"class {out.touch_cls:2d}"
    moved = "-"
    if out.markers_pred is not None and out.markers_reference is not None:
        d = np.linalg.norm(out.markers_pred - out.markers_reference, axis=1)
        moved = f"{np.nanmax(d):5.2f} mm"
    ref = s.get("reference", {}).get("touch", {}).get("state", "-")
    contact = "" if out.contact is None else f" | {_contact_text(out.contact)}"
    if out.inversion is not None:
        contact += f" | {_inversion_text(out.inversion)}"
    return (
        f"t {out.t:9.3f} s | touch {touch} | markers moved {moved}{contact} | "
        f"reference {ref} | "
        f"{s['fps_out']:5.1f} fps | latency p50 {s['latency_ms_p50']} ms "
        f"p99 {s['latency_ms_p99']} ms | dropped {s['dropped']} malformed "
        f"{s['malformed']} reconnects {s['reconnects']}"
    )


def _contact_text(reading: Any) -> str:
    """A ``ContactReading`` in a few words."""
    fingers = ", ".join(
        f"{f.face} ({f.u_mm:.0f}, {f.v_mm:.0f}) mm {f.force_n:.2f}"
        + (f" ± {f.force_sigma_n:.2f}" if getattr(f, "force_sigma_n", None) is not None else "")
        + " N"
        for f in reading.fingers
    )
    return (
        f"contact {reading.count}"
        + (f": {fingers}" if fingers else "")
        + (f" hover {reading.p_hover:.2f}")
    )


def _inversion_text(inv: InversionFrame) -> str:
    """An :class:`InversionFrame` in a few words."""
    fingers = ", ".join(
        f"{f.face} ({f.u_mm:.1f}, {f.v_mm:.1f}) mm "
        + (f"{f.force_n:.2f} N" if f.contact else f"hover {f.height_mm:.1f} mm")
        for f in inv.fingers
    )
    return f"inversion {inv.n_fingers}" + (f": {fingers}" if fingers else "") + f" {inv.fit_ms:.1f} ms"
