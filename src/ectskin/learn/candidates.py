"""Touch model choice: classical candidates beside the paper's TouchMLP, chosen on validation.

``ectskin train touch DATA OUT --model NAME`` (:func:`ectskin.learn.train.train`, ``model=``):

==================  =====================================================================
``mlp``             the paper's TouchMLP alone (the default; the run is as without a choice)
``auto``            every candidate below; the best validation accuracy is selected
``gbt``             gradient-boosted trees (``HistGradientBoostingClassifier``)
``random_forest``   ``RandomForestClassifier``
``logreg``          multinomial ``LogisticRegression`` (lbfgs)
``knn``             k-nearest-neighbour vote
==================  =====================================================================

The classical candidates are a ``Pipeline(StandardScaler, classifier)`` with the settings of
:data:`SETTINGS` (assumed: common defaults, not tuned), fit on the run's **training** split (a
seeded random subsample of at most :data:`MAX_TRAIN` frames, for speed: consecutive frames are
strongly correlated, so a subsample loses little) and scored on the **validation** split only.
Gradient boosting runs a fixed number of iterations (``early_stopping=False``): nothing it does
looks at the validation or test split. The test split is never used to choose.

Selection (:func:`select_candidate`): the highest validation accuracy; on a tie the earlier in
:data:`PREFERENCE` wins: the paper's MLP, then the simpler model (logistic regression, k-NN,
random forest, gradient boosting).

Files of the run directory (beside the MLP's ``model.pt`` when the MLP was trained):

* ``candidates.json`` (:func:`write_candidates` / :func:`read_candidates`): every candidate with
  its validation accuracy, fit seconds, training frames used and settings; the one selected and
  why; the seed and the fingerprints of the training and validation data. Written last and
  atomically: it is what tells evaluation and inference which model the run answers with.
* ``model.skops`` (:func:`save_classical` / :func:`load_classical`): the selected classical model
  with its metadata, saved with ``skops.io``. A model file is untrusted input: it is loaded with
  an explicit list of trusted types (:data:`SKOPS_TRUSTED`), and what it holds must be the
  pipeline of one of the four classifiers; anything else is refused, naming the file.

scikit-learn and skops are imported on use (they cost a second at start-up).

Size: the candidates' fitting, selection and both of their files (model.skops with its
trusted-type checks, candidates.json) share the names and settings defined here; split apart
they would import each other.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from collections.abc import Mapping
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import atomic_write, read_json_object, write_json_atomic
from ectskin.learn.checkpoint import check_layout
from ectskin.learn.data.touch import TouchData

log = logging.getLogger(__name__)

__all__ = [
    "CANDIDATES_FILE",
    "CLASSICAL",
    "CLASSICAL_FILE",
    "MAX_TRAIN",
    "PREFERENCE",
    "SETTINGS",
    "SKOPS_TRUSTED",
    "TOUCH_MODELS",
    "CandidateResult",
    "ClassicalConfig",
    "ClassicalModel",
    "accuracy",
    "candidate_names",
    "fit_candidates",
    "fit_classical",
    "load_classical",
    "read_candidates",
    "save_classical",
    "select_candidate",
    "selected_model",
    "write_candidates",
]

#: the classical candidates
CLASSICAL = ("gbt", "random_forest", "logreg", "knn")
#: the values of ``--model``: the paper's MLP (default), every candidate, or one of them
TOUCH_MODELS = ("mlp", "auto", *CLASSICAL)
#: tie order of :func:`select_candidate`: on equal validation accuracy the earlier wins
PREFERENCE = ("mlp", "logreg", "knn", "random_forest", "gbt")
#: largest training subsample per classical candidate (frames; a seeded random draw)
MAX_TRAIN = {"gbt": 20_000, "random_forest": 20_000, "logreg": 50_000, "knn": 10_000}
#: the classifiers' settings (assumed: common defaults, not tuned on any data)
SETTINGS: dict[str, dict[str, Any]] = {
    "gbt": {"max_iter": 100, "learning_rate": 0.1, "max_leaf_nodes": 31, "early_stopping": False},
    "random_forest": {"n_estimators": 100},
    "logreg": {"C": 1.0, "max_iter": 1000},
    "knn": {"n_neighbors": 5},
}
CANDIDATES_FILE = "candidates.json"
CLASSICAL_FILE = "model.skops"
#: format tag and version of the dict a ``model.skops`` holds
SKOPS_FORMAT = "ectskin.touch_classical"
SKOPS_VERSION = 1
CANDIDATES_FORMAT = "ectskin.touch_candidates"
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
    _fast: Any = field(default=None, repr=False)  # the boosted trees as arrays (_BoostedTrees)

    @property
    def config(self) -> ClassicalConfig:
        return ClassicalConfig(self.n_pairs, self.n_classes)

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(B, n_pairs) frames → (B, n_classes) float32 probabilities; a class absent from the
        training frames has probability 0."""
        x = np.asarray(x, dtype=np.float64)
        out = np.zeros((x.shape[0], self.n_classes), dtype=np.float32)
        if x.shape[0]:
            with one_thread():  # OpenMP threads for a few frames only add overhead
                proba = None
                if self.name == "random_forest":
                    proba = _forest_proba(self.estimator, x)
                elif self.name == "gbt":
                    if self._fast is None:
                        self._fast = _BoostedTrees.of(self.estimator) or False
                    proba = self._fast.predict_proba(x) if self._fast else None
                if proba is None:
                    proba = self.estimator.predict_proba(x)
            out[:, self.estimator.classes_] = proba
        return out

    def predict(self, x: np.ndarray) -> np.ndarray:
        """(B, n_pairs) frames → (B,) int64 classes (the most probable)."""
        return self.predict_proba(x).argmax(axis=1).astype(np.int64)


@dataclass
class CandidateResult:
    """One candidate scored on the validation split (what ``candidates.json`` stores)."""

    name: str
    val_accuracy: float
    fit_seconds: float
    n_train_used: int
    settings: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "val_accuracy": self.val_accuracy,
            "fit_seconds": self.fit_seconds,
            "n_train_used": self.n_train_used,
            "settings": dict(self.settings),
        }


def _forest_proba(pipeline: Any, x: np.ndarray) -> np.ndarray | None:
    """``pipeline.predict_proba(x)`` of a Pipeline(StandardScaler, RandomForestClassifier) without
    scikit-learn's per-tree dispatch (which costs milliseconds for one frame): the mean of the
    trees' normalised leaf fractions, as ``RandomForestClassifier.predict_proba`` computes it.
    None when a tree is not the plain single-output kind this path reads."""
    scaler, forest = pipeline.steps[0][1], pipeline.steps[1][1]
    z32 = np.ascontiguousarray(_standardised(scaler, x), dtype=np.float32)  # the trees' dtype
    n_classes = len(forest.classes_)
    total = np.zeros((x.shape[0], n_classes))
    for tree in forest.estimators_:
        p = tree.tree_.predict(z32)
        if p.ndim != 2 or p.shape[1] < n_classes:
            return None
        p = p[:, :n_classes]
        norm = p.sum(axis=1, keepdims=True)
        norm[norm == 0.0] = 1.0
        total += p / norm
    return total / len(forest.estimators_)


def _standardised(scaler: Any, x: np.ndarray) -> np.ndarray:
    """``scaler.transform(x)`` (a fitted StandardScaler) without its input checks."""
    z = x.copy()
    if scaler.with_mean:
        z -= scaler.mean_
    if scaler.with_std:
        z /= scaler.scale_
    return z


@dataclass
class _BoostedTrees:
    """The trees of a fitted ``HistGradientBoostingClassifier`` as flat arrays, walked for all
    trees at once: scikit-learn walks them one Python call per tree (19 classes x 100
    iterations = 1 900 calls, tens of milliseconds for one frame). Same arithmetic: a sample goes
    left where ``x[feature] <= threshold`` (a NaN where the node sends missing values), the raw
    score is the baseline plus the leaves' values per class, the probabilities its softmax
    (sigmoid for two classes)."""

    scaler: Any
    feature: np.ndarray  # (N,) per node of all trees
    threshold: np.ndarray  # (N,)
    missing_left: np.ndarray  # (N,) bool
    left: np.ndarray  # (N,) global node index
    right: np.ndarray  # (N,)
    leaf: np.ndarray  # (N,) bool
    value: np.ndarray  # (N,)
    roots: np.ndarray  # (T,) the root node of each tree
    tree_class: np.ndarray  # (T, K) one-hot: the class column each tree adds to
    baseline: np.ndarray  # (K,)

    @classmethod
    def of(cls, pipeline: Any) -> _BoostedTrees | None:
        """The arrays of ``pipeline`` (StandardScaler, HistGradientBoostingClassifier), or None
        when its trees are of a kind this path does not walk (categorical splits) or scikit-learn
        stores them otherwise."""
        try:
            scaler, gbt = pipeline.steps[0][1], pipeline.steps[1][1]
            k = int(gbt.n_trees_per_iteration_)
            trees = [(j, p.nodes) for it in gbt._predictors for j, p in enumerate(it)]
            baseline = np.asarray(gbt._baseline_prediction, dtype=np.float64).reshape(-1)
            nodes = np.concatenate([n for _, n in trees])
            if np.any(nodes["is_categorical"]) or baseline.size != k:
                return None
        except (AttributeError, KeyError, TypeError, ValueError, IndexError):
            return None
        sizes = np.array([len(n) for _, n in trees])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        shift = np.repeat(starts, sizes)
        onehot = np.zeros((len(trees), k))
        onehot[np.arange(len(trees)), [j for j, _ in trees]] = 1.0
        return cls(
            scaler=scaler,
            feature=nodes["feature_idx"].astype(np.int64),
            threshold=nodes["num_threshold"].astype(np.float64),
            missing_left=nodes["missing_go_to_left"].astype(bool),
            left=nodes["left"].astype(np.int64) + shift,
            right=nodes["right"].astype(np.int64) + shift,
            leaf=nodes["is_leaf"].astype(bool),
            value=nodes["value"].astype(np.float64),
            roots=starts.astype(np.int64),
            tree_class=onehot,
            baseline=baseline,
        )

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(B, F) frames → (B, n_classes seen in training) probabilities."""
        z = _standardised(self.scaler, x)
        node = np.broadcast_to(self.roots, (z.shape[0], self.roots.size)).copy()  # (B, T)
        rows = np.arange(z.shape[0])[:, None]
        while True:
            inner = ~self.leaf[node]
            if not inner.any():
                break
            v = z[rows, self.feature[node]]
            go_left = np.where(np.isnan(v), self.missing_left[node], v <= self.threshold[node])
            step = np.where(go_left, self.left[node], self.right[node])
            node = np.where(inner, step, node)
        raw = self.value[node] @ self.tree_class + self.baseline  # (B, K)
        if raw.shape[1] == 1:  # two classes: one tree per iteration, a logit
            p1 = 1.0 / (1.0 + np.exp(-raw[:, 0]))
            return np.stack([1.0 - p1, p1], axis=1)
        raw -= raw.max(axis=1, keepdims=True)
        e = np.exp(raw)
        return e / e.sum(axis=1, keepdims=True)


def candidate_names(model: str) -> tuple[str, ...]:
    """The candidates ``--model`` trains, in :data:`PREFERENCE` order: all for "auto"."""
    check_option("model", model, TOUCH_MODELS)
    return PREFERENCE if model == "auto" else (model,)


def accuracy(pred: np.ndarray, y: np.ndarray) -> float:
    """Fraction of ``pred == y`` (NaN for no samples)."""
    return float(np.mean(np.asarray(pred) == np.asarray(y))) if len(y) else math.nan


# --------------------------------------------------------------------------- fitting
def _estimator(name: str, seed: int) -> Any:
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


def fit_candidates(
    names: tuple[str, ...],
    train: TouchData,
    val: TouchData,
    *,
    seed: int = 0,
    threads: int | None = 1,
) -> tuple[dict[str, CandidateResult], dict[str, ClassicalModel]]:
    """Fit the classical ``names`` on ``train`` and score each on ``val`` (accuracy), with
    ``threads`` native threads (:func:`thread_limit`)."""
    results: dict[str, CandidateResult] = {}
    models: dict[str, ClassicalModel] = {}
    for name in names:
        with thread_limit(threads):
            model, used, seconds = fit_classical(name, train, seed=seed)
        acc = accuracy(model.predict(val.x), val.y)
        results[name] = CandidateResult(name, acc, seconds, used, model.settings)
        models[name] = model
        log.info(
            "touch candidate %s: validation accuracy %.4f (fit on %d frames, %.1f s)",
            name,
            acc,
            used,
            seconds,
        )
    return results, models


def select_candidate(val_accuracy: Mapping[str, float]) -> tuple[str, str]:
    """The candidate with the highest validation accuracy, ties to the earlier in
    :data:`PREFERENCE`; returns (name, the reason in words)."""
    if not val_accuracy:
        raise EctskinError("select_candidate: no candidates")
    unknown = sorted(set(val_accuracy) - set(PREFERENCE))
    if unknown:
        raise EctskinError(f"select_candidate: unknown candidate(s) {', '.join(unknown)}")
    finite = {k: v for k, v in val_accuracy.items() if math.isfinite(v)}
    if not finite:
        raise EctskinError("select_candidate: no candidate has a finite validation accuracy")
    best = max(finite.values())
    tied = [k for k in PREFERENCE if finite.get(k) == best]
    name = tied[0]
    if len(val_accuracy) == 1:
        return name, "the only candidate (--model asked for it)"
    why = f"highest validation accuracy ({best:.4f})"
    if len(tied) > 1:
        why += f", tied with {', '.join(tied[1:])}: the paper's MLP, then the simpler model wins"
    return name, why


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
        "settings": _plain(model.settings),
        "estimator": model.estimator,
    }
    data = skops.io.dumps(payload)
    return atomic_write(path, lambda fh: fh.write(data))


def _plain(value: Any) -> Any:
    """Settings as str/int/float/bool/None, lists and dicts (what the file stores)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def load_classical(path: str | Path, *, layout: Any = None) -> ClassicalModel:
    """Load a ``model.skops`` written by :func:`save_classical`; refuse anything else.

    Only the types of skops' defaults and :data:`SKOPS_TRUSTED` are loaded (nothing else in the
    file is run); the loaded object must then be the payload of :func:`save_classical` with a
    ``Pipeline(StandardScaler, classifier)`` of the named candidate, whose sizes agree with the
    stored ones (and with ``layout``, a SensorLayout, when given). Every refusal is an
    EctskinError naming the file.
    """
    import skops.io
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler

    path = Path(path)
    if not path.is_file():
        raise EctskinError(f"{path}: no such model file")
    try:
        untrusted = skops.io.get_untrusted_types(file=path)
    except Exception as exc:  # noqa: BLE001 - not a zip, no schema, damaged...
        raise EctskinError(f"{path}: not a readable skops model file ({_why(exc)})") from None
    refused = sorted(set(untrusted) - set(SKOPS_TRUSTED))
    if refused:
        raise EctskinError(
            f"{path}: holds type(s) outside the trusted list: {', '.join(refused)}; ectskin "
            "loads only the four touch classifiers from a model file, and nothing in it was run"
        )
    try:
        payload = skops.io.load(path, trusted=list(SKOPS_TRUSTED))
    except Exception as exc:  # noqa: BLE001 - refused or damaged content
        raise EctskinError(f"{path}: not a readable skops model file ({_why(exc)})") from None
    if not isinstance(payload, dict) or payload.get("format") != SKOPS_FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise EctskinError(
            f"{path}: not an ectskin touch model (expected format {SKOPS_FORMAT!r}, found "
            f"{found!r})"
        )
    version = payload.get("version")
    if not isinstance(version, int) or version > SKOPS_VERSION:
        raise EctskinError(
            f"{path}: model file version {version!r} is newer than this ectskin reads "
            f"(<= {SKOPS_VERSION}); upgrade ectskin"
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


def _why(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return type(exc).__name__ + (f": {text[0][:200]}" if text else "")


# --------------------------------------------------------------------------- candidates.json
def write_candidates(run_dir: str | Path, doc: Mapping[str, Any]) -> Path:
    """Write ``run_dir/candidates.json`` atomically (strict JSON)."""
    return write_json_atomic(Path(run_dir) / CANDIDATES_FILE, {"format": CANDIDATES_FORMAT, **doc})


def read_candidates(run_dir: str | Path) -> dict[str, Any] | None:
    """The run's ``candidates.json`` checked, or None when the run has none (an MLP run).

    It must name the ``model`` choice, the ``selected`` candidate (one of ``candidates``) and
    per candidate a ``val_accuracy``; a selected classical model needs ``model.skops``.
    """
    run = Path(run_dir)
    path = run / CANDIDATES_FILE
    if not path.exists():
        return None
    doc = read_json_object(path, "candidates file")
    if doc.get("format") != CANDIDATES_FORMAT:
        raise EctskinError(
            f"{path}: expected format {CANDIDATES_FORMAT!r}, found {doc.get('format')!r}"
        )
    choice = doc.get("model")
    if choice not in TOUCH_MODELS or choice == "mlp":
        raise EctskinError(
            f"{path}: field 'model' is {choice!r}, expected one of {TOUCH_MODELS[1:]}"
        )
    cands = doc.get("candidates")
    if not isinstance(cands, dict) or not cands or not set(cands) <= set(PREFERENCE):
        raise EctskinError(
            f"{path}: field 'candidates' must map candidate names ({', '.join(PREFERENCE)}) to "
            f"their results, found {cands!r:.200}"
        )
    for name, c in cands.items():
        if not isinstance(c, dict) or not isinstance(c.get("val_accuracy"), int | float | None):
            raise EctskinError(f"{path}: candidate {name!r} has no 'val_accuracy'")
    selected = doc.get("selected")
    if selected not in cands:
        raise EctskinError(
            f"{path}: field 'selected' is {selected!r}, expected one of {sorted(cands)}"
        )
    if selected != "mlp" and not (run / CLASSICAL_FILE).is_file():
        raise EctskinError(
            f"{path}: selects {selected!r} but the run has no {CLASSICAL_FILE}; train again"
        )
    if selected == "mlp" and not (run / "model.pt").is_file():
        raise EctskinError(f"{path}: selects the MLP but the run has no model.pt; train again")
    return doc


def selected_model(run_dir: str | Path) -> str:
    """The model a run answers with: "mlp" (no ``candidates.json``, or it selects the MLP) or
    the name of the classical candidate in ``model.skops``."""
    doc = read_candidates(run_dir)
    return "mlp" if doc is None else str(doc["selected"])
