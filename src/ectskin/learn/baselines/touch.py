"""Trivial and classical baselines of touch recognition beside the paper's TouchMLP ("a model is
only as good as its margin").

On :class:`~ectskin.learn.data.touch.TouchData`, fit on train, evaluated on test:

==================  =====================================================================
``majority``        the most frequent training class for every frame
``logreg``          standardised features → multinomial LogisticRegression (lbfgs)
``random_forest``   RandomForestClassifier, 100 trees, ``n_jobs`` workers
``knn``             standardised features → 5-nearest-neighbour vote
==================  =====================================================================

Speed on ~100 000 training samples: the classical models are fit on a random subsample of at
most ``max_train`` samples (default 10 000 for random forest and k-NN, 50 000 for logistic
regression). Samples of consecutive frames are strongly correlated, so a subsample loses little;
the number used is reported in each result.

Every result holds per-sample predictions so that the evaluation computes the paper's metrics
(accuracy and misclassified counts) on exactly the same samples.
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.learn.baselines.base import subsample
from ectskin.learn.data.touch import TouchData

log = logging.getLogger(__name__)

TOUCH_BASELINES = ("majority", "logreg", "random_forest", "knn")

__all__ = [
    "TOUCH_BASELINES",
    "TouchBaselineResult",
    "majority_baseline",
    "sklearn_touch_baseline",
    "touch_baselines",
]


@dataclass
class TouchBaselineResult:
    """A touch baseline evaluated on the test samples.

    ``pred`` is (n_test,) int64 predicted classes; ``n_misclassified`` = frames with
    pred ≠ truth; ``n_train_used`` = training samples the model was fit on.
    """

    name: str
    accuracy: float
    n_test: int
    n_misclassified: int
    pred: np.ndarray
    n_train_used: int
    fit_seconds: float
    params: dict[str, Any] = field(default_factory=dict)

    def to_metrics(self) -> dict[str, Any]:
        """Plain numbers for ``metrics.json`` (no arrays)."""
        return {
            "accuracy": self.accuracy,
            "n_test_frames": self.n_test,
            "n_misclassified": self.n_misclassified,
            "n_train_used": self.n_train_used,
            "fit_seconds": self.fit_seconds,
            "params": dict(self.params),
        }


def _check_touch(train: TouchData, test: TouchData) -> None:
    if train.n_samples == 0 or test.n_samples == 0:
        raise EctskinError(
            f"touch baselines need training and test samples, got {train.n_samples} and "
            f"{test.n_samples}"
        )
    if train.n_pairs != test.n_pairs:
        raise EctskinError(
            f"touch baselines: training data has {train.n_pairs} channels, test data {test.n_pairs}"
        )


def _touch_result(
    name: str, pred: np.ndarray, test: TouchData, n_used: int, t0: float, params: dict
) -> TouchBaselineResult:
    pred = np.asarray(pred, dtype=np.int64)
    wrong = int(np.count_nonzero(pred != test.y))
    res = TouchBaselineResult(
        name=name,
        accuracy=1.0 - wrong / test.n_samples,
        n_test=test.n_samples,
        n_misclassified=wrong,
        pred=pred,
        n_train_used=int(n_used),
        fit_seconds=time.perf_counter() - t0,
        params=params,
    )
    log.info(
        "touch baseline %s: accuracy %.4f (%d of %d wrong), %.1f s",
        name,
        res.accuracy,
        wrong,
        test.n_samples,
        res.fit_seconds,
    )
    return res


def majority_baseline(train: TouchData, test: TouchData) -> TouchBaselineResult:
    """Predict the most frequent training class (lowest class on ties) for every test frame."""
    _check_touch(train, test)
    t0 = time.perf_counter()
    cls = int(np.bincount(train.y).argmax())
    pred = np.full(test.n_samples, cls, dtype=np.int64)
    return _touch_result("majority", pred, test, train.n_samples, t0, {"class": cls})


def sklearn_touch_baseline(
    name: str,
    train: TouchData,
    test: TouchData,
    *,
    max_train: int | None = None,
    seed: int = 0,
    n_jobs: int = 2,
) -> TouchBaselineResult:
    """Fit a classical classifier (``"logreg"``, ``"random_forest"`` or ``"knn"``) on (a random
    subsample of at most ``max_train``) training frames and predict the test frames."""
    # scikit-learn is imported here, not at the top: it costs a second at start-up
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.linear_model import LogisticRegression
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    _check_touch(train, test)
    defaults = {"logreg": 50_000, "random_forest": 10_000, "knn": 10_000}
    check_option("name", name, tuple(defaults))
    if max_train is None:
        max_train = defaults[name]
    rng = np.random.default_rng(seed)
    idx = subsample(train.n_samples, max_train, rng)
    t0 = time.perf_counter()
    if name == "logreg":
        params = {"C": 1.0, "max_iter": 1000}
        model = make_pipeline(StandardScaler(), LogisticRegression(**params))
    elif name == "random_forest":
        params = {"n_estimators": 100, "random_state": seed}
        model = RandomForestClassifier(n_jobs=n_jobs, **params)
    else:
        params = {"n_neighbors": 5}
        model = make_pipeline(StandardScaler(), KNeighborsClassifier(n_jobs=n_jobs, **params))
    x_train = train.x[idx].astype(np.float64)
    y_train = train.y[idx]
    if np.unique(y_train).size < 2:
        # scikit-learn refuses one-class problems; the answer is that class
        pred = np.full(test.n_samples, int(y_train[0]), dtype=np.int64)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.fit(x_train, y_train)
        pred = model.predict(test.x.astype(np.float64))
    params["max_train"] = max_train
    return _touch_result(name, pred, test, idx.size, t0, params)


def touch_baselines(
    train: TouchData,
    test: TouchData,
    *,
    methods: Sequence[str] = TOUCH_BASELINES,
    seed: int = 0,
    n_jobs: int = 2,
    max_train: dict[str, int] | None = None,
) -> dict[str, TouchBaselineResult]:
    """Run the touch baselines ``methods`` (default all of :data:`TOUCH_BASELINES`)."""
    out: dict[str, TouchBaselineResult] = {}
    for m in methods:
        if m not in TOUCH_BASELINES:
            raise EctskinError(
                f"unknown touch baseline {m!r}; allowed: {', '.join(TOUCH_BASELINES)}"
            )
        if m == "majority":
            out[m] = majority_baseline(train, test)
        else:
            out[m] = sklearn_touch_baseline(
                m, train, test, max_train=(max_train or {}).get(m), seed=seed, n_jobs=n_jobs
            )
    return out
