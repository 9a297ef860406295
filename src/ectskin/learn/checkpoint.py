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

What a file must hold before anything is built from it (:func:`read_checkpoint`,
:func:`load_checkpoint`):

* only tensors and plain values (anything else is refused by the loader, and the error never
  suggests loading it another way);
* finite numbers in every tensor of ``state_dict`` and in ``normalizer`` (a model with NaN weights
  or statistics would answer with garbage, not fail);
* a ``config`` whose sizes agree with the shapes of the ``state_dict`` tensors (and with the
  layout, where one is given), checked *before* the model is built, so a crafted size such as
  ``n_pairs = 10**9`` is one error naming the field instead of an allocation of the size it
  asks for.
"""

from __future__ import annotations

import logging
import math
import pickle
import re
import warnings
from collections.abc import Mapping
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
        raise EctskinError(f"{path}: not a readable ectskin checkpoint ({_why(exc)})") from None
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
    check_finite(path, payload["state_dict"], payload["normalizer"])
    return payload


def _why(exc: BaseException) -> str:
    """Why ``torch.load(weights_only=True)`` refused a file, in our words: torch's own message
    suggests loading the file with ``weights_only=False`` (running whatever it holds), which a
    model file from elsewhere must never be, so it is not passed on."""
    text = str(exc)
    if isinstance(exc, pickle.UnpicklingError):
        found = re.search(r"GLOBAL ([\w.]+)", text)
        if found:
            return (
                f"it holds a Python object ({found.group(1)}) besides tensors and plain values; "
                "ectskin loads nothing else from a model file, and nothing in it was run"
            )
        return "not a torch checkpoint, or damaged: its content is not tensors and plain values"
    if isinstance(exc, EOFError) or "zip archive" in text or "central directory" in text:
        return "damaged or cut short: its zip archive is incomplete"
    first = text.strip().splitlines()[0] if text.strip() else ""
    if re.search(r"weights_only|pickle", first, re.IGNORECASE):
        first = ""
    return type(exc).__name__ + (f": {first[:200]}" if first else "")


def check_finite(path: str | Path, state_dict: Mapping[str, Any], normalizer: Any) -> None:
    """Refuse a checkpoint whose weights, buffers or normalisation statistics are not finite
    numbers (NaN, inf; a non-finite statistic is stored as None), naming the file and the
    tensor or field."""
    for name, value in state_dict.items():
        if not isinstance(value, torch.Tensor):
            raise EctskinError(
                f"{path}: state_dict entry {name!r} is a {type(value).__name__}, not a tensor"
            )
        if value.is_floating_point() or value.is_complex():
            bad = ~torch.isfinite(value)
            if bool(bad.any()):
                raise EctskinError(
                    f"{path}: tensor {name!r} of the state dict holds non-finite values "
                    f"({int(bad.sum())} of {value.numel()} NaN or inf); the file is damaged or "
                    "comes from a training that diverged, and is not used"
                )
    bad_field = _nonfinite_field(normalizer)
    if bad_field is not None:
        raise EctskinError(
            f"{path}: normaliser field {bad_field} is not a finite number (NaN, inf or null); "
            "the file is damaged or comes from a training that diverged, and is not used"
        )


def _nonfinite_field(value: Any, where: str = "") -> str | None:
    """The path (``['x']['mean'][3]``) of the first non-finite number or None in ``value`` (a
    normaliser's plain values), or None when all are finite."""
    if isinstance(value, Mapping):
        items = ((f"{where}[{k!r}]", v) for k, v in value.items())
    elif isinstance(value, list | tuple):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(value))
    elif isinstance(value, torch.Tensor):
        return None if bool(torch.isfinite(value).all()) else where or "(the tensor)"
    elif value is None:
        return where or "(the value)"
    elif isinstance(value, bool | str):
        return None
    elif isinstance(value, int | float):
        return None if math.isfinite(value) else where or "(the value)"
    else:
        return None
    for sub, v in items:
        found = _nonfinite_field(v, sub)
        if found is not None:
            return found
    return None


def config_from_dict(kind: str, d: dict[str, Any], source: str | Path | None = None) -> Any:
    """Rebuild the config dataclass of ``kind`` from a plain dict; unknown fields are errors."""
    cls = MODELS[kind][1]
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - names)
    where = f"{source}: config" if source else "config"
    if unknown:
        raise EctskinError(
            f"{where}: unknown {cls.__name__} field(s) {', '.join(unknown)} "
            f"(written by a newer ectskin?)"
        )
    try:
        return cls(**d)
    except EctskinError as exc:  # "C2DTConfig.window must be an integer >= 1, got 0"
        raise EctskinError(f"{where}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{where}: invalid {cls.__name__} ({exc})") from None


def check_state_dict(path: str | Path, kind: str, config: Any, state_dict: Mapping) -> None:
    """Refuse a ``config`` whose sizes disagree with the shapes of the ``state_dict`` tensors,
    before a model is built from it: the model class names, per tensor, the config field of each
    dimension (``state_shapes``) and the key prefix of each stack of layers (``layer_stacks``).
    A model built from a config that passes is no larger than the tensors the file holds."""
    model_cls = MODELS[kind][0]
    for field, prefix in model_cls.layer_stacks.items():
        layers = {k[len(prefix) :].split(".")[0] for k in state_dict if k.startswith(prefix)}
        found = len(layers)
        if int(getattr(config, field)) != found:
            raise EctskinError(
                f"{path}: config field {field!r} is {getattr(config, field)!r} but the state dict "
                f"holds {found} such layer(s) ({prefix}*); the file is damaged or was edited"
            )
    for name, dims in model_cls.state_shapes(config).items():
        tensor = state_dict.get(name)
        if not isinstance(tensor, torch.Tensor):
            raise EctskinError(
                f"{path}: the state dict has no tensor {name!r}, which a {type(config).__name__} "
                "of the stored config needs; the file is damaged or was edited"
            )
        shape = tuple(tensor.shape)
        want = tuple(int(getattr(config, d)) if isinstance(d, str) else d for d in dims)
        if shape == want:
            continue
        if len(shape) != len(want):
            raise EctskinError(
                f"{path}: tensor {name!r} of the state dict has shape {shape}, the stored config "
                f"gives {want}; the file is damaged or was edited"
            )
        i = next(i for i, (a, b) in enumerate(zip(shape, want)) if a != b)
        what = f"config field {dims[i]!r} is {want[i]!r}" if isinstance(dims[i], str) else ""
        raise EctskinError(
            f"{path}: {what or 'the stored config'} but tensor {name!r} of the state dict has "
            f"shape {shape} (size {shape[i]} there); the file is damaged or was edited"
        )


def check_layout(path: str | Path, config: Any, layout: Any) -> None:
    """Refuse a model whose sizes do not fit ``layout`` (a :class:`~ectskin.layout.SensorLayout`):
    more channels than its pairs, other touch classes (TouchMLP), other markers or electrodes
    (C2DT); the error names the file and the field."""
    # (config field, the layout's number, what it counts, whether fewer is fine)
    checks = [("n_pairs", layout.n_pairs, "electrode pairs", True)]
    if hasattr(config, "n_classes"):
        checks.append(("n_classes", layout.n_classes, "touch classes", False))
    if hasattr(config, "n_markers"):
        checks.append(("n_markers", layout.n_markers, "markers", False))
    if getattr(config, "desc_dim", 0):
        checks.append(("n_electrodes", layout.n_electrodes, "electrodes", False))
    for field, n, what, fewer_ok in checks:
        value = int(getattr(config, field))
        if value > n or (value < n and not fewer_ok):
            raise EctskinError(
                f"{path}: config field {field!r} is {value}, but layout {layout.name!r} has {n} "
                f"{what}; the model was trained for another skin"
            )


def load_checkpoint(
    path: str | Path,
    *,
    kind: str | None = None,
    n_pairs: int | None = None,
    layout: Any = None,
    map_location: str | torch.device = "cpu",
) -> tuple[nn.Module, Any, dict]:
    """Rebuild a model from ``path`` alone: returns ``(model, config, payload)``.

    The model is in eval mode on ``map_location``. ``kind`` ("touch_mlp" or "c2dt") refuses a
    file of the other kind; ``n_pairs`` refuses a model trained on another channel count;
    ``layout`` (a SensorLayout) one trained for another skin (:func:`check_layout`). Before the
    model is built, its config is checked against the state dict (:func:`check_state_dict`).
    """
    path = Path(path)
    payload = read_checkpoint(path, map_location=map_location)
    if kind is not None and payload["kind"] != kind:
        raise EctskinError(f"{path}: holds a {payload['kind']!r} model, expected a {kind!r} model")
    config = config_from_dict(payload["kind"], payload["config"], path)
    check_state_dict(path, payload["kind"], config, payload["state_dict"])
    if n_pairs is not None:
        check_channels(path, config, n_pairs)
    if layout is not None:
        check_layout(path, config, layout)
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
