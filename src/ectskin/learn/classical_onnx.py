"""Single frames of a classical touch model through ONNX Runtime: the live engine's fast path.

scikit-learn answers one frame slowly: ``predict_proba`` checks its input on every call, and
trees are evaluated one call per tree (a random forest of 100 trees; gradient boosting with 19
classes x 100 iterations = 1 900 trees), which costs milliseconds per frame where the live engine
has a few. :class:`OnnxClassifier` exports the fitted ``Pipeline(StandardScaler, classifier)``
once with skl2onnx (the ONNX project's converter for scikit-learn, released against its
versions: no reading of scikit-learn's internals here) and runs it in an ONNX Runtime session on
one thread, in float32 (the dtype of the live engine's frames). Per-frame figures:
``benchmarks/bench_candidates.py`` and ``BENCHMARKS.md``.

The export is checked before it is used: on fixed random frames around the training data (the
scaler's ``mean_`` and ``scale_``) it must give what ``estimator.predict_proba`` gives, to
``atol = 1e-4`` (float32 against scikit-learn's float64), else :class:`EctskinError`. Where
two classes tie (a forest's equal votes), float32 rounding may pick the other one.

Only :data:`ONNX_KINDS` are exported. k-NN is not: its ONNX graph computes the distance to every
stored training frame, slower per frame than scikit-learn's tree search.

skl2onnx, ``onnx`` and ONNX Runtime come with the ``live`` extra and are imported on use (they
cost a second at start-up); :func:`available` says whether they import.
"""

from __future__ import annotations

import importlib.util
import time
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.learn.runtime import single_thread_session

__all__ = ["ONNX_KINDS", "OnnxClassifier", "available"]

#: the classical candidates whose single frames ONNX Runtime answers
ONNX_KINDS = ("gbt", "random_forest", "logreg")
#: the standard ONNX opset of the export (ONNX Runtime >= 1.14 runs it)
OPSET = 17
_TOLERANCE = 1e-4
_CHECK_FRAMES = 64


def available() -> bool:
    """Whether skl2onnx and ONNX Runtime are installed."""
    return all(importlib.util.find_spec(m) is not None for m in ("skl2onnx", "onnxruntime"))


def _hist_gbt_converter(scope: Any, operator: Any, container: Any) -> None:
    """skl2onnx's converter of ``HistGradientBoostingClassifier``, with list attributes of
    Python booleans passed as 0/1 integers.

    skl2onnx 1.20 sets ``nodes_missing_value_tracks_true`` to ``False`` for leaves, which
    protobuf >= 7 refuses in an integer list ("Expected an int, got a boolean"), so the export
    of any boosted model fails there; as integers the values mean the same.
    """
    # skl2onnx is an optional package (the live extra): imported on use
    from skl2onnx.operator_converters.random_forest import (
        convert_sklearn_random_forest_classifier,
    )

    add_node = container.add_node

    def add_node_with_ints(*args: Any, **attrs: Any) -> Any:
        for key, value in attrs.items():
            if isinstance(value, list) and any(isinstance(v, bool) for v in value):
                attrs[key] = [int(v) for v in value]
        return add_node(*args, **attrs)

    container.add_node = add_node_with_ints
    try:
        convert_sklearn_random_forest_classifier(scope, operator, container)
    finally:
        del container.add_node  # the class's own method again


class OnnxClassifier:
    """``estimator.predict_proba`` (a fitted ``Pipeline(StandardScaler, classifier)`` on
    ``n_features`` inputs) exported to ONNX and run by ONNX Runtime on one thread.

    ``__call__`` takes (B, n_features) frames and returns (B, len(classes_)) float32
    probabilities, columns in the order of the classifier's ``classes_``. ``export_s`` is how
    long the export and its check took; ``name`` is what error messages call the model.
    """

    def __init__(self, estimator: Any, n_features: int, *, name: str = "model") -> None:
        if not available():
            raise EctskinError(
                f"{name}: the ONNX export of a classical model needs skl2onnx and onnxruntime: "
                "pip install 'ectskin[live]'"
            )
        # optional packages (the live extra): imported on use
        from skl2onnx import convert_sklearn
        from skl2onnx.common.data_types import FloatTensorType
        from sklearn.ensemble import HistGradientBoostingClassifier

        t0 = time.perf_counter()
        self.name = name
        self.n_features = int(n_features)
        classifier = estimator.steps[-1][1]
        try:
            proto = convert_sklearn(
                estimator,
                initial_types=[("x", FloatTensorType([None, self.n_features]))],
                options={id(classifier): {"zipmap": False}},  # probabilities as one tensor
                custom_conversion_functions={HistGradientBoostingClassifier: _hist_gbt_converter},
                target_opset=OPSET,
            ).SerializeToString()
        except Exception as exc:  # the exporter raises many types; name the model
            raise EctskinError(f"{name}: export to ONNX failed: {exc}") from exc
        self._session = single_thread_session(proto, name)
        outputs = [o.name for o in self._session.get_outputs()]
        self._output = "probabilities" if "probabilities" in outputs else outputs[-1]
        self._check(estimator)
        self.export_s = time.perf_counter() - t0

    def _check(self, estimator: Any) -> None:
        """Refuse an export that does not reproduce ``estimator.predict_proba``."""
        scaler = estimator.steps[0][1]
        gen = np.random.default_rng(0)
        z = gen.standard_normal((_CHECK_FRAMES, self.n_features))
        mean, scale = getattr(scaler, "mean_", None), getattr(scaler, "scale_", None)
        x = z * (1.0 if scale is None else scale) + (0.0 if mean is None else mean)
        x = x.astype(np.float32)
        want = estimator.predict_proba(x.astype(np.float64))
        got = self(x)
        if got.shape != want.shape or not np.allclose(got, want, rtol=_TOLERANCE, atol=_TOLERANCE):
            diff = float(np.max(np.abs(got - want))) if got.shape == want.shape else None
            raise EctskinError(
                f"{self.name}: the ONNX export does not reproduce scikit-learn's predict_proba "
                f"(shape {got.shape} vs {want.shape}, largest difference {diff})"
            )

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(B, n_features) frames → (B, n_classes seen in training) float32 probabilities."""
        a = np.ascontiguousarray(x, dtype=np.float32)
        if a.ndim != 2 or a.shape[1] != self.n_features:
            raise EctskinError(
                f"{self.name} (ONNX): frames must have shape (B, {self.n_features}), got {a.shape}"
            )
        return self._session.run([self._output], {"x": a})[0]
