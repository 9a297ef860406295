"""Single-frame inference with ONNX Runtime: the live engine's fast path.

A live engine answers one frame at a time. Run eagerly, PyTorch spends most of a small model's
time dispatching its operators one by one, not computing. :class:`OnnxModel` exports a trained
model (with its output map, e.g. softmax or ContactNet's decode) once, for a batch of one, with
``torch.onnx.export`` and runs it in an ONNX Runtime session on one thread, which answers a
frame faster (``benchmarks/bench_live.py`` measures both; the figures are in BENCHMARKS.md).

The export is checked before it is used: on fixed random inputs it must give what the PyTorch
model gives, to ``rtol = atol = 1e-4`` (float32 kernels differ in the last bits), else
:class:`EctskinError`. Batches stay on PyTorch
(:func:`ectskin.learn.predict.base.forward_batches`).

ONNX Runtime, ``onnx`` and ``onnxscript`` (the exporter's) come with the ``live`` extra;
:func:`available` says whether they import.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import logging
import time
import warnings
from collections.abc import Callable, Sequence

import numpy as np
import torch

from ectskin._check import EctskinError

#: the runtimes a predictor can answer single frames with
RUNTIMES = ("onnx", "torch")
_TOLERANCE = 1e-4


def available() -> bool:
    """Whether ONNX Runtime and the exporter's packages are installed."""
    return all(importlib.util.find_spec(m) is not None for m in ("onnxruntime", "onnxscript"))


#: loggers of the exporter that report its own progress and internals at WARNING
_EXPORT_LOGGERS = ("torch.onnx", "onnxscript", "onnx_ir")


def single_thread_session(proto: bytes, name: str = "model"):
    """An ONNX Runtime session of the serialised model ``proto`` on one thread, sequential, CPU,
    logging errors only: one frame at a time, beside the engine's other work. A model the
    runtime cannot load (an opset too new, ...) is an error naming ``name``."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.log_severity_level = 3  # errors only
    try:
        return ort.InferenceSession(proto, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # the runtime raises many types; name the model
        raise EctskinError(f"{name}: ONNX Runtime cannot load the export: {exc}") from exc


@contextlib.contextmanager
def _quiet_export():
    """Keep the exporter's progress lines, warnings and log records out of the user's terminal
    (a failed export still raises)."""
    loggers = [logging.getLogger(n) for n in _EXPORT_LOGGERS]
    levels = [lg.level for lg in loggers]
    try:
        for lg in loggers:
            lg.setLevel(logging.ERROR)
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


class _WithOutput(torch.nn.Module):
    """``output(model(*inputs))`` as one module, so the export holds the output map too."""

    def __init__(self, model: torch.nn.Module, output: Callable | None) -> None:
        super().__init__()
        self.model = model
        self.output = output

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        out = self.model(*inputs)
        return out if self.output is None else self.output(out)


class OnnxModel:
    """``model`` (+ ``output``) exported for inputs of ``shapes`` (batch of one), run by ONNX
    Runtime on one thread.

    Parameters
    ----------
    model : a trained module; put in eval mode.
    shapes : the shape of each input, batch axis first (1).
    output : optional map of the model's output (traced into the export).
    name : what error messages call the model (its run directory).

    ``export_s`` is how long the export and its check took.
    """

    def __init__(
        self,
        model: torch.nn.Module,
        shapes: Sequence[tuple[int, ...]],
        *,
        output: Callable[[torch.Tensor], torch.Tensor] | None = None,
        name: str = "model",
    ) -> None:
        if not available():
            raise EctskinError(
                "the ONNX runtime needs onnxruntime and onnxscript: pip install 'ectskin[live]' "
                "(or answer with --runtime torch)"
            )

        t0 = time.perf_counter()
        self.name = name
        self.shapes = [tuple(int(n) for n in s) for s in shapes]
        self.input_names = [f"x{i}" for i in range(len(self.shapes))]
        wrapped = _WithOutput(model.eval(), output).eval()
        gen = torch.Generator().manual_seed(0)
        examples = tuple(torch.randn(*s, generator=gen) for s in self.shapes)
        try:
            with _quiet_export():
                program = torch.onnx.export(
                    wrapped, examples, dynamo=True, verbose=False, input_names=self.input_names
                )
            proto = program.model_proto.SerializeToString()
        except Exception as exc:  # the exporter raises many types; name the model
            raise EctskinError(f"{name}: export to ONNX failed: {exc}") from exc
        self._session = single_thread_session(proto, name)
        with torch.inference_mode():
            want = wrapped(*examples).numpy()
        got = self(*(e.numpy() for e in examples))
        if got.shape != want.shape or not np.allclose(
            got, want, rtol=_TOLERANCE, atol=_TOLERANCE, equal_nan=True
        ):
            diff = float(np.max(np.abs(got - want))) if got.shape == want.shape else None
            raise EctskinError(
                f"{name}: the ONNX export does not reproduce the PyTorch model (shape "
                f"{got.shape} vs {want.shape}, largest difference {diff}); use --runtime torch"
            )
        self.export_s = time.perf_counter() - t0

    def __call__(self, *inputs: np.ndarray) -> np.ndarray:
        """The output for one batch of one: each input of its export shape, float32."""
        feed = {}
        for name, shape, value in zip(self.input_names, self.shapes, inputs, strict=True):
            a = np.ascontiguousarray(value, dtype=np.float32)
            if a.shape != shape:
                raise EctskinError(
                    f"{self.name} (ONNX): input {name} must have shape {shape}, got {a.shape}"
                )
            feed[name] = a
        return self._session.run(None, feed)[0]
