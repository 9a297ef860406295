"""Self-describing model files: a model is rebuilt from the file alone.

A checkpoint is a ``torch.save`` of one dict of plain types and tensors::

    {"format": "ectskin.checkpoint", "version": 1,
     "kind": "touch_mlp" | "c2dt",          # which model class
     "config": asdict(config),              # its config dataclass
     "state_dict": model.state_dict(),      # weights + normalisation buffers
     "normalizer": {...},                   # the training-set statistics, as plain lists
     "extra": {...},                        # pair names, epoch, validation loss, ...
     "resume": {...}}                       # only in last.pt: optimizer, scheduler, epoch

Files are written atomically (:func:`ectskin._files.atomic_write`) and read with
``torch.load(..., weights_only=True)``: a model file is untrusted input, nothing in it is
executed. ``normalizer`` and ``extra`` hold plain values under the JSON policy of
:func:`ectskin._files.to_jsonable` (a non-finite number is stored as None). Every problem with a
file is an :class:`EctskinError` that names it.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import torch
from torch import nn

from ectskin._check import EctskinError
from ectskin._files import atomic_write, to_jsonable
from ectskin.learn.models import MODELS

logger = logging.getLogger(__name__)

FORMAT = "ectskin.checkpoint"
VERSION = 1


def atomic_torch_save(obj: Any, path: str | Path) -> Path:
    """``torch.save`` to ``path`` atomically: readers see the old file or the new, never half."""
    return atomic_write(path, lambda fh: torch.save(obj, fh))


def save_checkpoint(
    path: str | Path,
    model: nn.Module,
    config: Any = None,
    *,
    normalizer: Any = None,
    extra: dict[str, Any] | None = None,
    resume: dict[str, Any] | None = None,
) -> Path:
    """Write ``model`` (a :data:`MODELS` class) with its config to ``path`` atomically.

    ``config`` defaults to ``model.config``; ``normalizer`` is a dict of statistics (or an
    object with ``to_dict()``), stored as plain lists; ``extra`` any plain metadata; ``resume``
    the training state of ``last.pt`` (optimizer/scheduler state dicts, epoch).
    """
    model = getattr(model, "module", model)  # unwrap DistributedDataParallel
    kind = getattr(model, "kind", None)
    if kind not in MODELS:
        raise EctskinError(
            f"save_checkpoint: {type(model).__name__} is not an ectskin model "
            f"(known kinds: {', '.join(MODELS)})"
        )
    config = model.config if config is None else config
    if not isinstance(config, MODELS[kind][1]):
        raise EctskinError(
            f"save_checkpoint: a {kind!r} model needs a {MODELS[kind][1].__name__}, "
            f"got {type(config).__name__}"
        )
    payload = {
        "format": FORMAT,
        "version": VERSION,
        "kind": kind,
        "config": asdict(config),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "normalizer": to_jsonable(normalizer) if normalizer is not None else {},
        "extra": to_jsonable(extra or {}),
    }
    if resume is not None:
        payload["resume"] = resume
    return atomic_torch_save(payload, path)


def read_checkpoint(path: str | Path, *, map_location: str | torch.device = "cpu") -> dict:
    """Load and validate the raw payload dict of a checkpoint (no model is built)."""
    path = Path(path)
    if not path.is_file():
        raise EctskinError(f"{path}: no such checkpoint file")
    try:
        with warnings.catch_warnings():  # e.g. "unusual pickle protocol": the error says enough
            warnings.simplefilter("ignore", UserWarning)
            payload = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # noqa: BLE001 - corrupt zip, truncated file, refused pickle...
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise EctskinError(
            f"{path}: not a readable ectskin checkpoint ({type(exc).__name__}: {msg[:200]})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise EctskinError(
            f"{path}: not an ectskin checkpoint (expected format {FORMAT!r}, found {found!r})"
        )
    version = payload.get("version")
    if not isinstance(version, int) or version > VERSION:
        raise EctskinError(
            f"{path}: checkpoint version {version!r} is newer than this ectskin reads "
            f"(<= {VERSION}); upgrade ectskin"
        )
    for key, typ in (("kind", str), ("config", dict), ("state_dict", dict)):
        if not isinstance(payload.get(key), typ):
            raise EctskinError(f"{path}: field {key!r} is missing or not a {typ.__name__}")
    if payload["kind"] not in MODELS:
        raise EctskinError(
            f"{path}: unknown model kind {payload['kind']!r} (known: {', '.join(MODELS)})"
        )
    payload.setdefault("normalizer", {})
    payload.setdefault("extra", {})
    return payload


def config_from_dict(kind: str, d: dict[str, Any], source: str | Path | None = None) -> Any:
    """Rebuild the config dataclass of ``kind`` from a plain dict; unknown fields are errors."""
    cls = MODELS[kind][1]
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise EctskinError(
            f"{source or 'config'}: unknown {cls.__name__} field(s) {', '.join(unknown)} "
            f"(written by a newer ectskin?)"
        )
    return cls(**d)


def load_checkpoint(
    path: str | Path,
    *,
    kind: str | None = None,
    n_pairs: int | None = None,
    map_location: str | torch.device = "cpu",
) -> tuple[nn.Module, Any, dict]:
    """Rebuild a model from ``path`` alone: returns ``(model, config, payload)``.

    The model is in eval mode on ``map_location``. ``kind`` ("touch_mlp" or "c2dt") refuses a
    file of the other kind; ``n_pairs`` refuses a model trained on another channel count.
    """
    path = Path(path)
    payload = read_checkpoint(path, map_location=map_location)
    if kind is not None and payload["kind"] != kind:
        raise EctskinError(f"{path}: holds a {payload['kind']!r} model, expected a {kind!r} model")
    config = config_from_dict(payload["kind"], payload["config"], path)
    if n_pairs is not None:
        check_channels(path, config, n_pairs)
    model_cls = MODELS[payload["kind"]][0]
    model = model_cls(config)
    try:
        model.load_state_dict(payload["state_dict"], strict=True)
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()
        raise EctskinError(
            f"{path}: weights do not match the stored {type(config).__name__} "
            f"({' '.join(first[:3])[:300]})"
        ) from None
    model.to(map_location).eval()
    return model, config, payload


def check_channels(path: str | Path, config: Any, n_pairs: int, what: str = "dataset") -> None:
    """Raise "run/model.pt: model expects 28 channels, dataset has 27" on a mismatch."""
    if int(config.n_pairs) != int(n_pairs):
        raise EctskinError(f"{path}: model expects {config.n_pairs} channels, {what} has {n_pairs}")
