"""A classical touch model (a candidate of the touch model choice, :mod:`ectskin.learn.candidates`):
fit, answer frames, and its file ``model.skops``.

==================  =====================================================================
``gbt``             gradient-boosted trees (``HistGradientBoostingClassifier``)
``random_forest``   ``RandomForestClassifier``
``logreg``          multinomial ``LogisticRegression`` (lbfgs)
``knn``             k-nearest-neighbour vote
==================  =====================================================================

Each is a ``Pipeline(StandardScaler, classifier)`` with the settings of :data:`SETTINGS`
(assumed: common defaults, not tuned), fit (:func:`fit_classical`) on a seeded random subsample
of at most :data:`MAX_TRAIN` training frames, for speed: consecutive frames are strongly
correlated, so a subsample loses little. Gradient boosting runs a fixed number of iterations
(``early_stopping=False``): nothing it does looks at another split.

:class:`ClassicalModel` answers batches with scikit-learn's ``predict_proba`` and one frame with
an ONNX Runtime export of the same pipeline (:mod:`ectskin.learn.classical_onnx`, made on first
use; k-NN stays on scikit-learn).

``model.skops`` (:func:`save_classical` / :func:`load_classical`): the model with its metadata,
saved with ``skops.io``. A model file is untrusted input: it is loaded with an explicit list of
trusted types (:data:`SKOPS_TRUSTED`), and what it holds must be the pipeline of one of the
four classifiers; anything else is refused, naming the file.

scikit-learn and skops are imported on use (they cost a second at start-up).
"""

from __future__ import annotations

import logging
import time
import warnings
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import atomic_write, to_jsonable
from ectskin.learn import classical_onnx
from ectskin.learn.checkpoint import check_layout
from ectskin.learn.data.touch import TouchData

log = logging.getLogger(__name__)

__all__ = [
    "CLASSICAL",
    "CLASSICAL_FILE",
    "MAX_TRAIN",
    "SETTINGS",
    "SKOPS_TRUSTED",
    "ClassicalConfig",
    "ClassicalModel",
    "fit_classical",
    "load_classical",
    "one_thread",
    "save_classical",
    "thread_limit",
]

#: the classical candidates
CLASSICAL = ("gbt", "random_forest", "logreg", "knn")
#: largest training subsample per classical candidate (frames; a seeded random draw)
MAX_TRAIN = {"gbt": 20_000, "random_forest": 20_000, "logreg": 50_000, "knn": 10_000}
#: the classifiers' settings (assumed: common defaults, not tuned on any data)
SETTINGS: dict[str, dict[str, Any]] = {
    "gbt": {"max_iter": 100, "learning_rate": 0.1, "max_leaf_nodes": 31, "early_stopping": False},
    "random_forest": {"n_estimators": 100},
    "logreg": {"C": 1.0, "max_iter": 1000},
    "knn": {"n_neighbors": 5},
}
CLASSICAL_FILE = "model.skops"
#: format tag and version of the dict a ``model.skops`` holds
SKOPS_FORMAT = "ectskin.touch_classical"
SKOPS_VERSION = 1
#: the types outside skops' own defaults that a model.skops of the four classifiers holds (the
#: explicit list passed to ``skops.io.load``; any other type in a file is refused)
SKOPS_TRUSTED = (
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
    "sklearn.metrics._dist_metrics.EuclideanDistance64",
    "sklearn.neighbors._kd_tree.KDTree",
    "sklearn.tree._tree.Tree",
)


_CONTROLLER: list[Any] = []  # the process's threadpoolctl controller, made on first use


def thread_limit(threads: int | None) -> AbstractContextManager[Any]:
    """A block in which the native thread pools (OpenMP, BLAS) of scikit-learn use ``threads``
    threads (None: as they are). Results of the classical candidates do not depend on it, their
    speed does: on a small shared CPU OpenMP threads that wait for each other cost seconds."""
    if threads is None:
        return nullcontext()
    if not _CONTROLLER:
        # threadpoolctl costs start-up time and is needed only here: imported on use
        from threadpoolctl import ThreadpoolController

        _CONTROLLER.append(ThreadpoolController())
    return _CONTROLLER[0].limit(limits=int(threads))


def one_thread() -> AbstractContextManager[Any]:
    return thread_limit(1)


@dataclass(frozen=True)
class ClassicalConfig:
    """The sizes of a classical model, as a model config: channels and touch classes (what
    :func:`ectskin.learn.checkpoint.check_layout` and ``check_channels`` compare)."""

    n_pairs: int
    n_classes: int


@dataclass
class ClassicalModel:
    """A fitted classical candidate: ``estimator`` (the scikit-learn pipeline) on (n, n_pairs)
    calibrated frames, answering classes 0..n_classes−1."""

    name: str
    estimator: Any
    n_pairs: int
    n_classes: int
    pair_names: list[str]
    settings: dict[str, Any]
    # the ONNX Runtime export answering single frames: None before the first, False for none
    _onnx: classical_onnx.OnnxClassifier | bool | None = field(
        default=None, repr=False, compare=False
    )

    @property
    def config(self) -> ClassicalConfig:
        return ClassicalConfig(self.n_pairs, self.n_classes)

    def single_frame(self) -> classical_onnx.OnnxClassifier | None:
        """The ONNX Runtime export that answers one frame (:mod:`ectskin.learn.classical_onnx`),
        made and checked on the first call (well under a second to a few seconds, once per
        model). None where scikit-learn answers single frames too: k-NN, or the export is not
        possible here (skl2onnx or onnxruntime missing, or the export failed its check; said
        once, as a warning)."""
        if self._onnx is None:
            self._onnx = self._export() if self.name in classical_onnx.ONNX_KINDS else False
        return self._onnx if isinstance(self._onnx, classical_onnx.OnnxClassifier) else None

    def _export(self) -> classical_onnx.OnnxClassifier | bool:
        """:meth:`single_frame`'s export, or False (with a warning) where there is none."""
        if not classical_onnx.available():
            log.warning(
                "touch model %r answers single frames through scikit-learn (milliseconds per "
                "frame): its ONNX export needs skl2onnx and onnxruntime, pip install "
                "'ectskin[live]'",
                self.name,
            )
            return False
        try:
            return classical_onnx.OnnxClassifier(
                self.estimator, self.n_pairs, name=f"touch model {self.name!r}"
            )
        except EctskinError as exc:
            log.warning("%s; it answers single frames through scikit-learn", exc)
            return False

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(B, n_pairs) frames → (B, n_classes) float32 probabilities; a class absent from the
        training frames has probability 0. One frame (B = 1) goes through :meth:`single_frame`
        where there is one (in float32), a batch through scikit-learn's ``predict_proba``."""
        x = np.asarray(x)
        out = np.zeros((x.shape[0], self.n_classes), dtype=np.float32)
        if not x.shape[0]:
            return out
        onnx = self.single_frame() if x.shape[0] == 1 else None
        if onnx is not None:
            proba = onnx(x)
        else:
            with one_thread():  # OpenMP threads for a few frames only add overhead
                proba = self.estimator.predict_proba(x.astype(np.float64))
        out[:, self.estimator.classes_] = proba
        return out

    def predict(self, x: np.ndarray) -> np.ndarray:
        """(B, n_pairs) frames → (B,) int64 classes (the most probable)."""
        return self.predict_proba(x).argmax(axis=1).astype(np.int64)


# --------------------------------------------------------------------------- fitting
def _estimator(name: str, seed: int) -> Any:
    """The unfitted ``Pipeline(StandardScaler, classifier)`` of candidate ``name``."""
    from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
    from sklearn.linear_model import LogisticRegression
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    s = SETTINGS[name]
    if name == "gbt":
        clf = HistGradientBoostingClassifier(**s, random_state=seed)
    elif name == "random_forest":
        clf = RandomForestClassifier(**s, random_state=seed, n_jobs=1)
    elif name == "logreg":
        clf = LogisticRegression(**s)
    else:
        clf = KNeighborsClassifier(**s, n_jobs=1)
    return make_pipeline(StandardScaler(), clf)


def fit_classical(
    name: str, train: TouchData, *, seed: int = 0, max_train: int | None = None
) -> tuple[ClassicalModel, int, float]:
    """Fit classical candidate ``name`` on (a seeded subsample of at most ``max_train``, default
    :data:`MAX_TRAIN`, of) the training frames. Returns (model, frames used, fit seconds).

    The same name, data, seed and ``max_train`` give the same model (every random draw is
    seeded). Training frames of fewer than two classes are refused (scikit-learn needs two).
    """
    from sklearn.exceptions import ConvergenceWarning

    check_option("model", name, CLASSICAL)
    limit = MAX_TRAIN[name] if max_train is None else int(max_train)
    n = train.n_samples
    rng = np.random.default_rng(seed)
    idx = np.arange(n) if n <= limit else np.sort(rng.choice(n, size=limit, replace=False))
    y = train.y[idx]
    if np.unique(y).size < 2:
        raise EctskinError(
            f"touch model {name!r}: the training frames hold one class ({int(y[0])}); a classical "
            "model needs at least two"
        )
    estimator = _estimator(name, seed)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        estimator.fit(train.x[idx].astype(np.float64), y)
    seconds = time.perf_counter() - t0
    settings = {**SETTINGS[name], "max_train": limit, "seed": seed, "standardised": True}
    model = ClassicalModel(
        name=name,
        estimator=estimator,
        n_pairs=train.n_pairs,
        n_classes=int(train.n_classes),
        pair_names=[str(p) for p in train.pair_names],
        settings=settings,
    )
    return model, int(idx.size), seconds


# --------------------------------------------------------------------------- model.skops
def save_classical(path: str | Path, model: ClassicalModel) -> Path:
    """Write ``model`` to ``path`` (``skops.io``, atomically) with its sizes and settings."""
    import skops.io

    payload = {
        "format": SKOPS_FORMAT,
        "version": SKOPS_VERSION,
        "name": model.name,
        "n_pairs": int(model.n_pairs),
        "n_classes": int(model.n_classes),
        "pair_names": list(model.pair_names),
        "settings": to_jsonable(model.settings),  # plain values, as candidates.json holds them
        "estimator": model.estimator,
    }
    data = skops.io.dumps(payload)
    return atomic_write(path, lambda fh: fh.write(data))


def load_classical(path: str | Path, *, layout: Any = None) -> ClassicalModel:
    """Load a ``model.skops`` written by :func:`save_classical`; refuse anything else.

    Only the types of skops' defaults and :data:`SKOPS_TRUSTED` are loaded (nothing else in the
    file is run); the loaded object must then be the payload of :func:`save_classical` with a
    ``Pipeline(StandardScaler, classifier)`` of the named candidate, whose sizes agree with the
    stored ones (and with ``layout``, a SensorLayout, when given). Every refusal is an
    EctskinError naming the file.
    """
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler

    path = Path(path)
    payload = read_skops_payload(
        path, SKOPS_TRUSTED, SKOPS_FORMAT, SKOPS_VERSION, what="touch model",
        refusal="ectskin loads only the four touch classifiers from a model file",
    )
    name = payload.get("name")
    if name not in CLASSICAL:
        raise EctskinError(f"{path}: field 'name' is {name!r}, expected one of {CLASSICAL}")
    for key in ("n_pairs", "n_classes"):
        v = payload.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise EctskinError(f"{path}: field {key!r} must be an integer >= 1, found {v!r}")
    est = payload.get("estimator")
    want = type(_estimator(name, 0).steps[-1][1])
    if not (
        isinstance(est, Pipeline)
        and len(est.steps) == 2
        and type(est.steps[0][1]) is StandardScaler
        and type(est.steps[1][1]) is want
    ):
        raise EctskinError(
            f"{path}: field 'estimator' must be a Pipeline(StandardScaler, {want.__name__}) for "
            f"candidate {name!r}, found {_describe(est)}"
        )
    n_in = getattr(est.steps[0][1], "n_features_in_", None)
    classes = np.asarray(getattr(est.steps[1][1], "classes_", []))
    if n_in != payload["n_pairs"] or not (
        classes.size and classes.min() >= 0 and classes.max() < payload["n_classes"]
    ):
        raise EctskinError(
            f"{path}: the classifier (inputs {n_in}, classes {classes.tolist()}) disagrees with "
            f"the stored sizes (n_pairs {payload['n_pairs']}, n_classes {payload['n_classes']})"
        )
    names = payload.get("pair_names")
    if not isinstance(names, list) or len(names) != payload["n_pairs"]:
        names = [f"ch{i}" for i in range(payload["n_pairs"])]
    model = ClassicalModel(
        name=name,
        estimator=est,
        n_pairs=payload["n_pairs"],
        n_classes=payload["n_classes"],
        pair_names=[str(n) for n in names],
        settings=dict(payload.get("settings") or {}),
    )
    if layout is not None:
        check_layout(path, model.config, layout)
    return model


def _describe(obj: Any) -> str:
    if hasattr(obj, "steps"):
        return "Pipeline(" + ", ".join(type(s).__name__ for _, s in obj.steps) + ")"
    return type(obj).__name__


def read_skops_payload(
    path: Path, trusted: tuple[str, ...], fmt: str, version: int, *, what: str, refusal: str = ""
) -> dict[str, Any]:
    """The payload dict of an ectskin ``model.skops`` at ``path``: only skops' default types and
    ``trusted`` are loaded (a file holding any other type is refused before anything in it is
    run), and its ``format`` must be ``fmt`` with a ``version`` of at most ``version``. Every
    refusal is an EctskinError naming the file; ``what`` names the model kind in them,
    ``refusal`` says what is loaded when a type is refused."""
    import skops.io

    if not path.is_file():
        raise EctskinError(f"{path}: no such model file")
    try:
        untrusted = skops.io.get_untrusted_types(file=path)
    except Exception as exc:  # noqa: BLE001 - not a zip, no schema, damaged...
        raise EctskinError(f"{path}: not a readable skops model file ({_why(exc)})") from None
    refused = sorted(set(untrusted) - set(trusted))
    if refused:
        raise EctskinError(
            f"{path}: holds type(s) outside the trusted list: {', '.join(refused)}; "
            + (f"{refusal}, and " if refusal else "")
            + "nothing in it was run"
        )
    try:
        payload = skops.io.load(path, trusted=list(trusted))
    except Exception as exc:  # noqa: BLE001 - refused or damaged content
        raise EctskinError(f"{path}: not a readable skops model file ({_why(exc)})") from None
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise EctskinError(
            f"{path}: not an ectskin {what} (expected format {fmt!r}, found {found!r})"
        )
    got = payload.get("version")
    if not isinstance(got, int) or got > version:
        raise EctskinError(
            f"{path}: model file version {got!r} is newer than this ectskin reads "
            f"(<= {version}); upgrade ectskin"
        )
    return payload


def _why(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return type(exc).__name__ + (f": {text[0][:200]}" if text else "")
