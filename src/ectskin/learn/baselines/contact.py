"""Baselines of the contact task, fit on the training split and scored like the model.

Each baseline reads the window's last frame (standardised) and predicts the same columns as
:class:`~ectskin.learn.models.contact.ContactNet` (:data:`~ectskin.learn.models.contact.PRED_COLUMNS`,
one finger slot filled, the others copies), so one function computes the metrics of all:

==================  =====================================================================
``region_centre``   the touch classifier's answer turned into a point: logistic regression
                    (the strongest touch baseline) over no touch + the regions, the point is
                    the predicted region's centre; force = the mean training force, its σ
                    the training forces' standard deviation. Left out
                    (:func:`left_out`, with a note) on a layout without physical regions
``knn``             5 nearest training frames: count and hover by vote, face by vote among
                    frames in contact, (u, v) and force their mean
``ridge``           ridge regression of (u, v) and force on frames in contact; count, face and
                    hover by logistic regression
==================  =====================================================================

Classical models are fit on a seeded random subsample of at most ``max_train`` frames. The
``knn`` and ``ridge`` forces come with the σ of :mod:`ectskin.learn.contact_classical` (fit on
out-of-fold residuals of the training split).
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.learn.baselines.base import subsample
from ectskin.learn.data.contact import MAX_FINGERS, ContactData
from ectskin.learn.models.contact import PRED_COLUMNS, SLOT_COLUMNS

CONTACT_BASELINES = ("region_centre", "knn", "ridge")
MAX_TRAIN = 10000

__all__ = [
    "CONTACT_BASELINES",
    "MAX_TRAIN",
    "contact_baselines",
    "left_out",
    "contact_knn_baseline",
    "contact_ridge_baseline",
    "region_centre_baseline",
]


def _frames(data: ContactData) -> np.ndarray:
    return np.asarray(data.x[:, -1, :], dtype=np.float64)


def _pack(count, p_contact, p_hover, face, uv, force, force_sigma) -> np.ndarray:
    n = len(count)
    slot = np.column_stack([face, uv[:, 0], uv[:, 1], np.full(n, np.nan), force, force_sigma])
    out = np.empty((n, len(PRED_COLUMNS) + MAX_FINGERS * len(SLOT_COLUMNS)))
    out[:, 0], out[:, 1], out[:, 2] = count, p_contact, p_hover
    for s in range(MAX_FINGERS):
        a = len(PRED_COLUMNS) + s * len(SLOT_COLUMNS)
        out[:, a : a + len(SLOT_COLUMNS)] = slot
    return out


def _logreg(seed: int):
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    return make_pipeline(StandardScaler(), LogisticRegression(max_iter=200, random_state=seed))


def _fit_classes(model, x: np.ndarray, y: np.ndarray):
    """Fit ``model`` on (x, y), or a constant when y has one class; returns predict_proba-like
    callable giving P(class == 1) and a predict callable."""
    classes = np.unique(y)
    if classes.size == 1:
        c = classes[0]
        return (lambda z: np.full(len(z), float(c == 1))), (lambda z: np.full(len(z), c))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(x, y)
    pos = list(model.classes_).index(1) if 1 in model.classes_ else None

    def proba(z):
        return model.predict_proba(z)[:, pos] if pos is not None else np.zeros(len(z))

    return proba, model.predict


def region_centre_baseline(
    train: ContactData, test: ContactData, region_centres: np.ndarray, *, seed: int = 0
) -> np.ndarray:
    """Region classifier → the region's centre. ``region_centres`` (n_regions + 1, 3): (face
    index, u, v) of each region id (row 0 unused). Training frames of one class give that
    class for every frame (logistic regression needs two)."""
    idx = subsample(train.n_samples, MAX_TRAIN, np.random.default_rng(seed))
    x = _frames(train)[idx]
    region = train.group_region[train.group[idx]] * (train.count[idx] > 0)
    xt = _frames(test)
    classes = np.unique(region)
    if classes.size == 1:  # one class (e.g. every frame a press of one region): it, always
        r = np.full(len(xt), classes[0])
        p_contact = np.full(len(xt), float(classes[0] != 0))
    else:
        clf = _logreg(seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            clf.fit(x, region)
        proba = clf.predict_proba(xt)
        r = clf.classes_[proba.argmax(1)]
        p_contact = 1.0 - (proba[:, list(clf.classes_).index(0)] if 0 in clf.classes_ else 0.0)
    hover_p, _ = _fit_classes(_logreg(seed), x, train.hover[idx].astype(int))
    centre = region_centres[np.clip(r, 0, len(region_centres) - 1)]
    on = train.count > 0
    mean_force = float(train.force[on, 0].mean()) if on.any() else 0.0
    # the σ of a constant answer: the RMS of its error over the training frames in contact
    sd_force = float(train.force[on, 0].std()) if on.sum() > 1 else np.nan
    return _pack(
        (r > 0).astype(float),
        p_contact,
        hover_p(xt),
        centre[:, 0],
        centre[:, 1:],
        np.full(len(xt), mean_force),
        np.full(len(xt), sd_force),
    )


def contact_knn_baseline(
    train: ContactData, test: ContactData, *, seed: int = 0, k: int = 5
) -> np.ndarray:
    """k nearest standardised training frames (see the module docstring): the ``knn``
    candidate of the contact model choice (:mod:`ectskin.learn.contact_classical`)."""
    return _classical("knn", train, test, seed, k=k)


def contact_ridge_baseline(train: ContactData, test: ContactData, *, seed: int = 0) -> np.ndarray:
    """Ridge for (u, v) and force, logistic regression for count, face and hover: the ``ridge``
    candidate of the contact model choice (:mod:`ectskin.learn.contact_classical`)."""
    return _classical("ridge", train, test, seed)


def _classical(name: str, train: ContactData, test: ContactData, seed: int, **kw) -> np.ndarray:
    # imported on use: contact_classical imports this package's base module
    from ectskin.learn import contact_classical as cc

    if name == "knn" and kw.get("k", 5) != cc.SETTINGS["knn"]["n_neighbors"]:
        raise EctskinError(f"contact k-NN baseline: k must be {cc.SETTINGS['knn']['n_neighbors']}")
    model, _, _ = cc.fit_contact_classical(name, train, seed=seed, max_train=MAX_TRAIN)
    return model.predict(test.x)


def left_out(train: ContactData) -> dict[str, str]:
    """{baseline: why} of the baselines that give no meaningful number on ``train``'s skin: the
    region centre where the layout has no physical regions (the virtual layout of a generic
    import: its "regions" are strips over the whole face, so the distance to their centre is no
    region error) or none at all."""
    if not train.regions_physical:
        return {
            "region_centre": "left out: the layout has no physical touch regions (a virtual "
            "layout of a generic import), so the distance to a region's centre is no region error"
        }
    return {}


def contact_baselines(
    train: ContactData, test: ContactData, region_centres: np.ndarray, *, seed: int = 0
) -> dict[str, tuple[np.ndarray, float]]:
    """{name: (predictions (n_test, columns), fit+predict seconds)} of :data:`CONTACT_BASELINES`
    but those :func:`left_out` names."""
    if train.n_samples == 0 or test.n_samples == 0:
        raise EctskinError("contact baselines: the training or test split is empty")
    out: dict[str, Any] = {}
    skip = left_out(train)
    for name, fn in (
        ("region_centre", lambda: region_centre_baseline(train, test, region_centres, seed=seed)),
        ("knn", lambda: contact_knn_baseline(train, test, seed=seed)),
        ("ridge", lambda: contact_ridge_baseline(train, test, seed=seed)),
    ):
        if name in skip:
            continue
        t0 = time.perf_counter()
        pred = fn()
        out[name] = (pred, time.perf_counter() - t0)
    return out
