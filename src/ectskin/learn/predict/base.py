"""What every predictor shares: :class:`Predictor`, :func:`as_input` and :func:`forward_batches`.

A predictor (:class:`~ectskin.learn.predict.touch.TouchPredictor`,
:class:`~ectskin.learn.predict.track.TrackPredictor`,
:class:`~ectskin.learn.predict.contact.ContactPredictor`) rebuilds its model from a run
directory's ``model.pt`` alone (see :mod:`ectskin.learn.checkpoint`). The training-set
normalisation lives in the model's buffers, so every predictor takes *calibrated* readouts
(paper Eq. 2) exactly as the data sets hold them; :func:`as_input` checks them at the door.

Calls run in eval mode under ``torch.inference_mode`` on the CPU by default (latency figures:
``benchmarks/bench_train.py`` and ``BENCHMARKS.md``). ``use_runtime("onnx")`` answers single
frames with an ONNX Runtime export of the model instead (:mod:`ectskin.learn.runtime`, the live
engine's default); batches stay on PyTorch.

:func:`forward_batches` is the one batched inference path: the predictors and the evaluation of
a run (:mod:`ectskin.learn.tasks`) both run their model through it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ectskin._check import EctskinError
from ectskin.learn.checkpoint import load_checkpoint
from ectskin.learn.runtime import RUNTIMES, OnnxModel

__all__ = ["Predictor", "as_input", "forward_batches"]


def forward_batches(
    model: torch.nn.Module,
    inputs: Sequence[np.ndarray | torch.Tensor | None],
    *,
    batch_size: int | None = None,
    output: Callable[[torch.Tensor], torch.Tensor] | None = None,
    device: torch.device | None = None,
) -> np.ndarray:
    """``model(*inputs)`` in eval mode under ``torch.inference_mode``, ``batch_size`` samples at a
    time (all at once when None), on ``device`` (default: the device of the model's buffers).

    ``inputs`` are arrays (or tensors) with the samples on the first axis, e.g. touch frames
    (n, n_pairs) or track windows (n, k, n_pairs) and initial coordinates (n, M, 3); None passes
    None (a C2DT without prior). Arrays are taken as float32. ``output`` maps each batch's output
    (e.g. softmax, argmax). Returns the batches' outputs concatenated, as numpy.
    """
    if device is None:
        device = next(model.buffers()).device
    n = int(inputs[0].shape[0])
    size = n if batch_size is None else batch_size
    if model.training:
        model.eval()
    parts = []
    with torch.inference_mode():
        for a in range(0, n, max(size, 1)) if n else (0,):
            args = [None if v is None else _as_tensor(v[a : a + size], device) for v in inputs]
            out = model(*args)
            if output is not None:
                out = output(out)
            parts.append(out.cpu().numpy())
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _as_tensor(value: np.ndarray | torch.Tensor, device: torch.device) -> torch.Tensor:
    if isinstance(value, torch.Tensor):
        return value.to(device)
    return torch.from_numpy(np.ascontiguousarray(value, dtype=np.float32)).to(device)


def _model_file(run_dir: str | Path) -> Path:
    path = Path(run_dir)
    return path / "model.pt" if path.is_dir() else path


def as_input(
    name: str, value: Any, shape: tuple[int, ...], owner: str, channel_names: list[str]
) -> tuple[torch.Tensor, bool]:
    """A float32 tensor (B, *shape) from one sample of ``shape`` or a batch; returns
    (tensor, batched). A non-finite value is an error naming its index (and channel, when
    the last axis is the channel axis, i.e. ``channel_names`` is given)."""
    try:
        arr = np.ascontiguousarray(value, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise EctskinError(f"{owner}: {name} must be numeric; {exc}") from None
    batched = arr.ndim == len(shape) + 1
    if arr.shape[int(batched) :] != shape:
        want = ", ".join(map(str, shape))
        raise EctskinError(
            f"{owner}: {name} must have shape ({want}) or (B, {want}), got {arr.shape}"
        )
    if not np.isfinite(arr).all():
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        label = f" (channel {channel_names[bad[-1]]!r})" if channel_names else ""
        raise EctskinError(f"{owner}: {name} is not finite at index {bad}{label}: {arr[bad]}")
    return torch.from_numpy(arr if batched else arr[None]), batched


class Predictor:
    """A trained model for live use (module docstring): rebuilt from a run's checkpoint, with
    its config, payload and channel names; subclasses set :attr:`kind` (the checkpoint kind)
    and give ``predict``."""

    kind = ""
    _onnx: OnnxModel | None = None  # single frames through ONNX Runtime (use_runtime)

    def __init__(self, model: torch.nn.Module, config: Any, payload: dict, source: str) -> None:
        self.model = model.eval()
        self.config = config
        self.payload = payload
        self.source = source
        self.device = next(model.buffers()).device
        extra = payload.get("extra", {})
        names = extra.get("pair_names") or []
        self.pair_names: list[str] = (
            [str(n) for n in names]
            if len(names) == config.n_pairs
            else [f"ch{i}" for i in range(config.n_pairs)]
        )

    @classmethod
    def from_run(
        cls, run_dir: str | Path, *, device: str | torch.device = "cpu", layout: Any = None
    ):
        """Load ``run_dir/model.pt`` (or the checkpoint file itself) on ``device``; with
        ``layout`` (the skin it will read) a model trained for another skin is refused before it
        is built (:func:`ectskin.learn.checkpoint.check_layout`)."""
        path = _model_file(run_dir)
        model, config, payload = load_checkpoint(
            path, kind=cls.kind, layout=layout, map_location=device
        )
        return cls(model, config, payload, str(path))

    @property
    def n_pairs(self) -> int:
        return int(self.config.n_pairs)

    # ------------------------------------------------------------------ runtime
    def _single_shapes(self) -> list[tuple[int, ...]]:
        """The model's input shapes for one sample, batch axis first."""
        raise NotImplementedError

    #: the map of the model's output predict applies: a function, or the name of the model's
    #: method (ContactNet's "decode"), or None
    _output: Any = None

    def _output_map(self) -> Callable[[torch.Tensor], torch.Tensor] | None:
        output = self._output
        return getattr(self.model, output) if isinstance(output, str) else output

    @property
    def runtime(self) -> str:
        """What answers single frames: "onnx" or "torch"."""
        return "torch" if self._onnx is None else "onnx"

    def use_runtime(self, runtime: str):
        """Answer single frames with ``runtime``: "onnx" exports the model once (seconds;
        checked against the PyTorch model, :class:`~ectskin.learn.runtime.OnnxModel`), "torch"
        runs it eagerly. Returns self."""
        if runtime not in RUNTIMES:
            raise EctskinError(f"runtime must be one of {RUNTIMES}, got {runtime!r}")
        self._onnx = None
        if runtime == "onnx" and self.model is not None:
            self._onnx = OnnxModel(
                self.model,
                self._single_shapes(),
                output=self._output_map(),
                name=f"{type(self).__name__}({self.source})",
            )
        return self

    def _forward(self, inputs: list[torch.Tensor | None], batched: bool) -> np.ndarray:
        """The (mapped) model output for ``inputs`` (batch first; None passes None)."""
        if self._onnx is not None and not batched:
            return self._onnx(*(v.numpy() for v in inputs if v is not None))
        return forward_batches(self.model, inputs, output=self._output_map(), device=self.device)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.source!r}, n_pairs={self.n_pairs})"
