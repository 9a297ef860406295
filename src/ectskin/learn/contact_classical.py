"""A classical contact model (a candidate of the contact model choice,
:mod:`ectskin.learn.contact_choice`): fit, answer windows, and its file ``model.skops``.

Each reads the window's **last frame** (as the contact baselines do,
:mod:`ectskin.learn.baselines.contact`) and answers the columns of
:class:`~ectskin.learn.models.contact.ContactNet` (:data:`PRED_COLUMNS`, then per finger slot
:data:`SLOT_COLUMNS`; one finger, copied into every slot). It is four parts, each a
``Pipeline(StandardScaler, estimator)`` (or a constant where the training frames hold one value):

* ``contact``: contact or not (finger count 0 / 1) and its probability;
* ``hover``: a finger hovering over the skin (frames without contact);
* ``face``: the face, fit on the frames in contact;
* ``regress``: (u, v) mm and force N of the finger, fit on the frames in contact.

==========  ============================================  ===================================
candidate   regression of (u, v, force)                   classifiers (contact, hover, face)
==========  ============================================  ===================================
``knn``     mean of the 5 nearest frames                  vote of the 5 nearest frames
``ridge``   ``RidgeCV`` (α in 1e−3..1e3)                  logistic regression
``gbt``     ``HistGradientBoostingRegressor`` per output  ``HistGradientBoostingClassifier``
``gp``      ``GaussianProcessRegressor`` (constant × RBF  logistic regression
            + white noise), on at most
            :data:`GP_MAX_TRAIN` frames in contact
==========  ============================================  ===================================

The ``knn`` and ``ridge`` candidates are the contact task's k-NN and ridge baselines (those
functions call :func:`fit_contact_classical`): fit with the same seed on the same split they
give the same predictions, so a choice among candidates that include them never loses to them.
The Gaussian process gives its own uncertainty: ``sigma_mm`` is the mean of its predictive
standard deviations of u and v (NaN for the others), ``force_sigma_n`` that of the force.
Forces are clipped at 0.

The other candidates' force σ (part ``force_sigma``, :func:`fit_force_sigma`) comes from errors
on frames the force model did not see: the training trials are split into
:data:`SIGMA_FOLDS` folds (seeded, by trial), the regression is refit on all folds but one and
answers that one, and a linear model of |error| on the standardised frame, scaled so that the
mean of (error / σ)² over those out-of-fold frames is 1, is the σ (at least
:data:`SIGMA_FLOOR_REL` of the mean |error|). The training split, not the validation split:
the contact baselines are fit where no validation split is at hand, and a candidate must
answer as its baseline does. A model.skops written before this part loads without it (σ NaN).

Training frames: a seeded random subsample of at most :data:`MAX_TRAIN`. The settings are
common defaults, not tuned on any data.

``model.skops`` (:func:`save_contact_classical` / :func:`load_contact_classical`): the model
with its sizes, saved with ``skops.io`` and loaded with an explicit list of trusted types
(:data:`SKOPS_TRUSTED`); every part must be the pipeline its candidate fits, else the file is
refused, naming it.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin._files import atomic_write, to_jsonable
from ectskin.learn.baselines.base import subsample
from ectskin.learn.checkpoint import check_layout
from ectskin.learn.classical import read_skops_payload
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS

__all__ = [
    "CONTACT_CLASSICAL",
    "GP_MAX_TRAIN",
    "MAX_TRAIN",
    "ContactClassical",
    "ContactClassicalConfig",
    "fit_contact_classical",
    "load_contact_classical",
    "save_contact_classical",
]

#: the classical contact candidates
CONTACT_CLASSICAL = ("knn", "ridge", "gbt", "gp")
#: largest training subsample (frames, a seeded random draw; the contact baselines' too)
MAX_TRAIN = 10_000
#: largest number of frames in contact a Gaussian process is fit on (its cost grows as n³)
GP_MAX_TRAIN = 2_000
#: the finger slots of the columns (ContactNet's)
MAX_FINGERS = 2
PARTS = ("contact", "hover", "face", "regress")
#: parts a model.skops may hold besides :data:`PARTS` (absent in files written before them)
OPTIONAL_PARTS = ("force_sigma",)
#: folds of the training trials whose out-of-fold force errors fit the force's σ
SIGMA_FOLDS = 3
#: the force's σ is at least this share of the mean out-of-fold |error|
SIGMA_FLOOR_REL = 0.05
#: ridge of the σ model (standardised frame features)
SIGMA_RIDGE = 1e-3
SKOPS_FORMAT = "ectskin.contact_classical"
SKOPS_VERSION = 1
#: types outside skops' defaults that a contact model.skops holds
SKOPS_TRUSTED = (
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
    "sklearn.gaussian_process.kernels.ConstantKernel",
    "sklearn.gaussian_process.kernels.Product",
    "sklearn.gaussian_process.kernels.RBF",
    "sklearn.gaussian_process.kernels.Sum",
    "sklearn.gaussian_process.kernels.WhiteKernel",
    "sklearn.metrics._dist_metrics.EuclideanDistance64",
    "sklearn.neighbors._kd_tree.KDTree",
)
#: the settings of each candidate (assumed: common defaults, not tuned)
SETTINGS: dict[str, dict[str, Any]] = {
    "knn": {"n_neighbors": 5},
    "ridge": {"alphas": [float(a) for a in np.logspace(-3, 3, 13)], "logreg_max_iter": 200},
    "gbt": {"max_iter": 200, "learning_rate": 0.1, "max_leaf_nodes": 31, "early_stopping": False},
    "gp": {"kernel": "constant * RBF + white", "normalize_y": True, "logreg_max_iter": 200},
}


@dataclass(frozen=True)
class ContactClassicalConfig:
    """The sizes of a classical contact model (what ``check_layout`` / ``check_channels``
    compare, and the window its predictor takes)."""

    n_pairs: int
    window: int
    n_faces: int


def _classifier(name: str, seed: int) -> Any:
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.linear_model import LogisticRegression
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    if name == "knn":
        clf: Any = KNeighborsClassifier(SETTINGS["knn"]["n_neighbors"])
    elif name == "gbt":
        s = SETTINGS["gbt"]
        clf = HistGradientBoostingClassifier(
            max_iter=100, learning_rate=s["learning_rate"], early_stopping=False, random_state=seed
        )
    else:
        clf = LogisticRegression(max_iter=SETTINGS[name]["logreg_max_iter"], random_state=seed)
    return make_pipeline(StandardScaler(), clf)


def _regressor(name: str, seed: int) -> Any:
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
    from sklearn.linear_model import RidgeCV
    from sklearn.neighbors import KNeighborsRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    s = SETTINGS[name]
    if name == "knn":
        reg: Any = KNeighborsRegressor(s["n_neighbors"])
    elif name == "ridge":
        reg = RidgeCV(alphas=np.asarray(s["alphas"]))
    elif name == "gbt":
        reg = HistGradientBoostingRegressor(**s, random_state=seed)
    else:
        kernel = ConstantKernel(1.0) * RBF(1.0) + WhiteKernel(0.1)
        reg = GaussianProcessRegressor(kernel, normalize_y=True, random_state=seed)
    return make_pipeline(StandardScaler(), reg)


def _fit_class(est: Any, x: np.ndarray, y: np.ndarray) -> Any:
    """``est`` fit on (x, y), or the one class (an int) when y holds one."""
    classes = np.unique(y)
    if classes.size == 0:
        return 0
    if classes.size == 1:
        return int(classes[0])
    est.fit(x, y)
    return est


def _proba1(part: Any, x: np.ndarray) -> np.ndarray:
    """P(class 1) of a fitted classifier part (a constant: 1 or 0)."""
    if isinstance(part, int):
        return np.full(len(x), float(part == 1))
    classes = list(part.classes_)
    return part.predict_proba(x)[:, classes.index(1)] if 1 in classes else np.zeros(len(x))


def _classes(part: Any, x: np.ndarray) -> np.ndarray:
    if isinstance(part, int):
        return np.full(len(x), part, dtype=np.float64)
    return np.asarray(part.predict(x), dtype=np.float64)


@dataclass
class ContactClassical:
    """A fitted classical contact candidate (see the module docstring)."""

    name: str
    parts: dict[str, Any]  # PARTS → a fitted pipeline, a constant class (int), a list (gbt)
    n_pairs: int
    window: int
    faces: list[str]
    face_extent: dict[str, Any]
    pair_names: list[str]
    settings: dict[str, Any]

    @property
    def config(self) -> ContactClassicalConfig:
        return ContactClassicalConfig(self.n_pairs, self.window, len(self.faces))

    def predict(self, x: np.ndarray) -> np.ndarray:
        """(B, k, n_pairs) windows (or (B, n_pairs) frames) → (B, 3 + S · 5) float64 columns."""
        x = np.asarray(x, dtype=np.float64)
        frames = x[:, -1, :] if x.ndim == 3 else x
        n = len(frames)
        if frames.ndim != 2 or frames.shape[1] != self.n_pairs:
            raise EctskinError(
                f"contact model {self.name!r}: frames must have {self.n_pairs} channels, got "
                f"shape {x.shape}"
            )
        from ectskin.learn.classical import one_thread

        with one_thread(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            p_contact = _proba1(self.parts["contact"], frames) if n else np.zeros(0)
            count = _classes(self.parts["contact"], frames) if n else np.zeros(0)
            p_hover = _proba1(self.parts["hover"], frames) if n else np.zeros(0)
            face = _classes(self.parts["face"], frames) if n else np.zeros(0)
            uvf, sigma, force_sigma = self._regress(frames)
        if self.name != "gp":
            force_sigma = force_sigma_of(self.parts.get("force_sigma"), frames)
        slot = np.column_stack([face, uvf[:, 0], uvf[:, 1], sigma, uvf[:, 2], force_sigma])
        out = np.empty((n, len(PRED_COLUMNS) + MAX_FINGERS * len(SLOT_COLUMNS)))
        out[:, 0], out[:, 1], out[:, 2] = count, p_contact, p_hover
        for s in range(MAX_FINGERS):
            a = len(PRED_COLUMNS) + s * len(SLOT_COLUMNS)
            out[:, a : a + len(SLOT_COLUMNS)] = slot
        return out

    def _regress(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n, 3) (u, v, force), (n,) sigma_mm and (n,) force_sigma_n (both the Gaussian
        process's own; NaN for the others)."""
        n = len(frames)
        reg = self.parts["regress"]
        sigma, force_sigma = np.full(n, np.nan), np.full(n, np.nan)
        if reg is None or not n:
            return np.zeros((n, 3)), sigma, force_sigma
        if self.name != "gp":
            return _predict_regress(self.name, reg, frames), sigma, force_sigma
        out, std = reg[-1].predict(reg[:-1].transform(frames), return_std=True)
        out = np.asarray(out, dtype=np.float64).reshape(n, 3)
        out[:, 2] = np.maximum(out[:, 2], 0.0)
        std = np.asarray(std).reshape(n, -1)
        return out, std[:, :2].mean(axis=1), std[:, min(2, std.shape[1] - 1)]


def _predict_regress(name: str, reg: Any, frames: np.ndarray) -> np.ndarray:
    """(n, 3) (u, v, force) of a fitted regression part (forces clipped at 0 but k-NN's)."""
    n = len(frames)
    if isinstance(reg, list):  # gbt: one regressor per output
        out = np.column_stack([r.predict(frames) for r in reg])
    else:
        out = reg.predict(frames)
    out = np.asarray(out, dtype=np.float64).reshape(n, 3)
    if name != "knn":  # the k-NN baseline's forces are means of forces >= 0
        out[:, 2] = np.maximum(out[:, 2], 0.0)
    return out


def _fit_regress(name: str, x: np.ndarray, target: np.ndarray, seed: int) -> Any:
    if name == "gbt":
        return [_regressor(name, seed).fit(x, target[:, j]) for j in range(target.shape[1])]
    return _regressor(name, seed).fit(x, target)


def fit_force_sigma(
    name: str, x: np.ndarray, target: np.ndarray, groups: np.ndarray, seed: int
) -> dict[str, Any] | None:
    """The force σ of candidate ``name`` (module docstring) from frames in contact ``x``
    (n, P), their (u, v, force) ``target`` (n, 3) and trial ``groups`` (n,): a dict of plain
    numbers (:func:`force_sigma_of` answers with it), or None with fewer than two trials."""
    trials = np.unique(groups)
    if trials.size < 2:
        return None
    fold_of = dict(zip(np.random.default_rng(seed + 2).permutation(trials),
                       np.arange(trials.size) % min(SIGMA_FOLDS, trials.size)))
    fold = np.array([fold_of[g] for g in groups])
    pred = np.empty(len(x))
    for k in np.unique(fold):
        held = fold == k
        if name == "gbt":  # one regressor per output: the force's alone
            reg = _regressor(name, seed).fit(x[~held], target[~held, 2])
            pred[held] = np.maximum(reg.predict(x[held]), 0.0)
        else:
            pred[held] = _predict_regress(name, _fit_regress(name, x[~held], target[~held], seed),
                                          x[held])[:, 2]
    err = np.abs(pred - target[:, 2])
    mean, scale = x.mean(0), np.maximum(x.std(0), 1e-12)
    z = np.c_[(x - mean) / scale, np.ones(len(x))]
    coef = np.linalg.solve(z.T @ z + SIGMA_RIDGE * len(x) * np.eye(z.shape[1]), z.T @ err)
    floor = max(SIGMA_FLOOR_REL * float(err.mean()), 1e-9)
    g = np.maximum(z @ coef, floor)
    factor = max(float(np.sqrt(np.mean((err / g) ** 2))), 1e-12)
    return {"mean": mean.tolist(), "scale": scale.tolist(), "coef": coef.tolist(),
            "floor": floor, "factor": factor, "n_frames": int(len(x)),
            "folds": int(np.unique(fold).size)}


def force_sigma_of(part: Any, frames: np.ndarray) -> np.ndarray:
    """(n,) force σ (N) of frames (n, P) by a :func:`fit_force_sigma` part (NaN: None)."""
    if part is None:
        return np.full(len(frames), np.nan)
    z = (frames - np.asarray(part["mean"])) / np.asarray(part["scale"])
    coef = np.asarray(part["coef"])
    return part["factor"] * np.maximum(z @ coef[:-1] + coef[-1], part["floor"])


def fit_contact_classical(
    name: str, train: Any, *, seed: int = 0, max_train: int | None = None
) -> tuple[ContactClassical, int, float]:
    """Fit contact candidate ``name`` on (a seeded subsample of at most ``max_train``, default
    :data:`MAX_TRAIN`, of) the frames of ``train`` (a ContactData). Returns (model, frames
    used, fit seconds). The same name, data and seed give the same model."""
    check_option("model", name, CONTACT_CLASSICAL)
    limit = MAX_TRAIN if max_train is None else int(max_train)
    rng = np.random.default_rng(seed)
    idx = subsample(train.n_samples, limit, rng)
    x = np.asarray(train.x[idx, -1, :], dtype=np.float64)
    on_all = np.minimum(train.count[idx], 1)
    t0 = time.perf_counter()
    parts: dict[str, Any] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parts["contact"] = _fit_class(_classifier(name, seed), x, on_all)
        parts["hover"] = _fit_class(_classifier(name, seed), x, train.hover[idx].astype(int))
        on = on_all > 0
        parts["face"], parts["regress"], parts["force_sigma"] = 0, None, None
        if on.any():
            xo = x[on]
            target = np.column_stack([train.uv[idx][on, 0], train.force[idx][on, 0]])
            parts["face"] = _fit_class(_classifier(name, seed), xo, train.face[idx][on, 0])
            if name == "gp" and len(xo) > GP_MAX_TRAIN:
                keep = subsample(len(xo), GP_MAX_TRAIN, np.random.default_rng(seed + 1))
                xo, target = xo[keep], target[keep]
            parts["regress"] = _fit_regress(name, xo, target, seed)
            if name != "gp":
                groups = np.asarray(train.group)[idx][on]
                parts["force_sigma"] = fit_force_sigma(name, xo, target, groups, seed)
    seconds = time.perf_counter() - t0
    settings = {**SETTINGS[name], "max_train": limit, "seed": seed, "standardised": True}
    if name == "gp":
        settings["gp_max_train"] = GP_MAX_TRAIN
    model = ContactClassical(
        name=name,
        parts=parts,
        n_pairs=int(train.x.shape[2]),
        window=int(train.x.shape[1]),
        faces=[str(f) for f in train.faces],
        face_extent={f: [list(a), list(b)] for f, (a, b) in train.face_extent.items()},
        pair_names=[str(p) for p in train.pair_names],
        settings=settings,
    )
    return model, int(idx.size), seconds


# --------------------------------------------------------------------------- model.skops
def save_contact_classical(path: str | Path, model: ContactClassical) -> Path:
    """Write ``model`` to ``path`` (``skops.io``, atomically) with its sizes and settings."""
    import skops.io

    payload = {
        "format": SKOPS_FORMAT,
        "version": SKOPS_VERSION,
        "name": model.name,
        "n_pairs": int(model.n_pairs),
        "window": int(model.window),
        "faces": list(model.faces),
        "face_extent": to_jsonable(model.face_extent),
        "pair_names": list(model.pair_names),
        "settings": to_jsonable(model.settings),
        "parts": dict(model.parts),
    }
    data = skops.io.dumps(payload)
    return atomic_write(path, lambda fh: fh.write(data))


def _want(name: str, part: str) -> type:
    """The estimator type candidate ``name`` fits for ``part``."""
    est = _regressor(name, 0) if part == "regress" else _classifier(name, 0)
    return type(est.steps[-1][1])


def _check_part(path: Path, name: str, part: str, value: Any, n_pairs: int) -> None:
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler

    if part != "regress" and isinstance(value, int) and not isinstance(value, bool):
        return  # a constant class
    if part == "regress" and value is None:
        return  # no frame in contact
    items = value if (part == "regress" and name == "gbt" and isinstance(value, list)) else [value]
    want = _want(name, part)
    for est in items:
        ok = (
            isinstance(est, Pipeline)
            and len(est.steps) == 2
            and type(est.steps[0][1]) is StandardScaler
            and type(est.steps[1][1]) is want
            and getattr(est.steps[0][1], "n_features_in_", None) == n_pairs
        )
        if not ok:
            raise EctskinError(
                f"{path}: part {part!r} must be a Pipeline(StandardScaler, {want.__name__}) on "
                f"{n_pairs} channels for candidate {name!r}, found {type(est).__name__}"
            )
    if part == "regress" and name == "gbt" and len(items) != 3:
        raise EctskinError(f"{path}: part 'regress' must hold 3 regressors, found {len(items)}")


def _check_force_sigma(path: Path, part: Any, n_pairs: int) -> None:
    """Refuse a ``force_sigma`` part that is not None or the plain numbers of
    :func:`fit_force_sigma` for ``n_pairs`` channels."""
    if part is None:
        return
    sizes = {"mean": n_pairs, "scale": n_pairs, "coef": n_pairs + 1}
    ok = isinstance(part, dict) and all(
        isinstance(part.get(k), list) and len(part[k]) == n
        and all(isinstance(v, float | int) and np.isfinite(v) for v in part[k])
        for k, n in sizes.items()
    ) and all(isinstance(part.get(k), float | int) and np.isfinite(part[k]) and part[k] > 0
              for k in ("floor", "factor"))
    if not ok:
        raise EctskinError(
            f"{path}: part 'force_sigma' must be None or a dict of mean, scale ({n_pairs} "
            f"numbers each), coef ({n_pairs + 1}), floor and factor (> 0), found "
            f"{type(part).__name__}"
        )


def load_contact_classical(path: str | Path, *, layout: Any = None) -> ContactClassical:
    """Load a ``model.skops`` written by :func:`save_contact_classical`; refuse anything else
    (an EctskinError naming the file). Only skops' default types and :data:`SKOPS_TRUSTED` are
    loaded; ``layout`` (a SensorLayout) refuses a model of another skin."""
    path = Path(path)
    payload = read_skops_payload(
        path, SKOPS_TRUSTED, SKOPS_FORMAT, SKOPS_VERSION, what="contact model"
    )
    name = payload.get("name")
    if name not in CONTACT_CLASSICAL:
        raise EctskinError(f"{path}: field 'name' is {name!r}, expected one of {CONTACT_CLASSICAL}")
    for key in ("n_pairs", "window"):
        v = payload.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise EctskinError(f"{path}: field {key!r} must be an integer >= 1, found {v!r}")
    faces = payload.get("faces")
    if not isinstance(faces, list) or not faces or not all(isinstance(f, str) for f in faces):
        raise EctskinError(f"{path}: field 'faces' must be a list of face names, found {faces!r}")
    parts = payload.get("parts")
    if not isinstance(parts, dict) or not set(PARTS) <= set(parts) <= {*PARTS, *OPTIONAL_PARTS}:
        raise EctskinError(
            f"{path}: field 'parts' must hold {', '.join(PARTS)} (and may hold "
            f"{', '.join(OPTIONAL_PARTS)})"
        )
    for part in PARTS:
        _check_part(path, name, part, parts[part], payload["n_pairs"])
    parts.setdefault("force_sigma", None)
    _check_force_sigma(path, parts["force_sigma"], payload["n_pairs"])
    names = payload.get("pair_names")
    if not isinstance(names, list) or len(names) != payload["n_pairs"]:
        names = [f"ch{i}" for i in range(payload["n_pairs"])]
    model = ContactClassical(
        name=name,
        parts=parts,
        n_pairs=payload["n_pairs"],
        window=payload["window"],
        faces=[str(f) for f in faces],
        face_extent=dict(payload.get("face_extent") or {}),
        pair_names=[str(n) for n in names],
        settings=dict(payload.get("settings") or {}),
    )
    if layout is not None:
        check_layout(path, model.config, layout)
    return model
