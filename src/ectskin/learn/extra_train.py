"""Recordings whose trials join a run's training split only (``TrainConfig.extra_train``).

A run's recording is split into training, validation and test trials; an *extra* recording adds
trials to the training split alone: the twin's coverage trials (:mod:`ectskin.twin.coverage`,
every region in every inflation state), or another session of the same skin. Validation, model
selection and the test stay on the run's own recording, so a number on the test split means what
it meant without them.

Each extra recording is calibrated against its own rest readouts with the run's reference (Eq. 2
per recording: a twin's or another session's absolute capacitances need not match the run's),
and must have the run's channels and classes. ``split.json`` names each file with its trial
digests (``extra_train``), so an evaluation fits the baselines on the same training trials
(:func:`with_extra`) and a changed or missing file is noticed (the baselines are then skipped,
saying why).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.io import read_recording
from ectskin.learn.splits import trial_digests

log = logging.getLogger(__name__)

__all__ = ["extra_identity", "extra_training_data", "join_training", "stored_extra", "with_extra"]


def _reference_of(reference: Any) -> Any:
    """The reference to calibrate an extra recording with: the run's, by name (a model fitted on
    the run's recording, "inflation", is fitted again on the extra one's own states)."""
    if isinstance(reference, str):
        return reference
    name = getattr(reference, "mode", None)  # an InflationModel: "inflation" or "inflation-offset"
    if not isinstance(name, str):
        raise EctskinError(
            f"extra training trials: the run's reference must be a reference name or an inflation "
            f"model to calibrate another recording with, got {type(reference).__name__}"
        )
    return name


def extra_training_data(
    task: Any, paths: Sequence[str | Path], *, reference: Any, options: Mapping[str, Any],
    run_digests: Mapping[str, str] | None = None,
) -> tuple[list[Any], list[dict[str, Any]]]:
    """The task's data sets of the recordings ``paths`` (each calibrated with ``reference`` against
    its own rest readouts; ``options``: the task's data set options, window and prior) and their
    identities for split.json (:func:`extra_identity`). An extra recording holding a trial of the
    run's own recording (``run_digests``, its trial digests) is refused: that trial could be a
    validation or test trial, and would then be trained on."""
    theirs = set((run_digests or {}).values())
    data, ident = [], []
    for p in paths:
        path = Path(p)
        if not path.is_file():
            raise EctskinError(f"extra training recording {path}: no such file")
        rec = read_recording(path)
        mine = extra_identity(path, rec)
        shared = sorted(n for n, d in mine["trial_digests"].items() if d in theirs)
        if shared:
            raise EctskinError(
                f"extra training recording {path}: {len(shared)} trial(s) ({shared[0]}, ...) hold "
                "the readouts of a trial of the run's own recording; extra trials must be other "
                "trials (the run's own are split into training, validation and test)"
            )
        ds = task.dataset(rec, reference=_reference_of(reference), **options)
        data.append(ds)
        ident.append(mine)
        log.info("extra training trials: %d trials, %d samples of %s", ds.n_groups,
                 ds.n_samples, path)
    return data, ident


def extra_identity(path: str | Path, rec: Any) -> dict[str, Any]:
    """How split.json names an extra training recording: its path and trial digests."""
    return {"file": str(Path(path).resolve()), "trial_digests": trial_digests(rec)}


def join_training(train: Any, extras: Sequence[Any], paths: Sequence[str | Path]) -> Any:
    """``train`` with the ``extras`` data sets' samples appended (their groups after the run's);
    an extra of other channels or classes is refused, naming its file. A contact extra may hold
    some of the run's inflation states only (``ContactData.aligned_to``)."""
    if not extras:
        return train
    extras = list(extras)
    for i, (ds, path) in enumerate(zip(extras, paths)):
        try:  # contact: some of the run's inflation states are enough
            extras[i] = ds = ds.aligned_to(train)
        except EctskinError as exc:
            raise EctskinError(f"extra training recording {path}: {exc}") from None
        for f in type(train).MATCH_FIELDS:
            a, b = getattr(ds, f), getattr(train, f)
            arrays = isinstance(a, np.ndarray) or isinstance(b, np.ndarray)
            if not (np.array_equal(a, b) if arrays else a == b):
                raise EctskinError(
                    f"extra training recording {path}: its {f} differ from the run's recording "
                    f"({getattr(ds, f)!r} vs {getattr(train, f)!r}); extra trials must come from "
                    "a skin with the same channels and regions"
                )
    return type(train).concat([train, *extras])


def _moved(path: Path, run_dir: str | Path | None) -> Path:
    """``path`` where it was at training, else a file of its name in the run's folder or one of
    the three above it (a reproduction's coverage.h5 beside ``runs/``, the folder moved or
    copied whole); its trial digests are checked after."""
    if path.is_file() or run_dir is None:
        return path
    folder = Path(run_dir).resolve()
    for d in (folder, *folder.parents[:3]):
        if (d / path.name).is_file():
            return d / path.name
    return path


def stored_extra(
    split: Mapping[str, Any], task: Any, *, reference: Any, options: Mapping[str, Any],
    run_dir: str | Path | None = None,
) -> tuple[list[Any], str]:
    """The data sets of the extra training recordings that a run's split.json names, for its
    baselines: ([], "") without any; ([], why) when one is missing or changed since training
    (its trial digests differ). A file gone from its path is looked for by name near
    ``run_dir`` (:func:`_moved`)."""
    items = list(split.get("extra_train") or [])
    if not items:
        return [], ""
    paths = [_moved(Path(item["file"]), run_dir) for item in items]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        return [], f"the run's extra training recording {missing[0]} is not there to fit them on"
    data, ident = extra_training_data(task, paths, reference=reference, options=options)
    for item, now in zip(items, ident):
        if dict(item.get("trial_digests") or {}) != now["trial_digests"]:
            return [], f"the run's extra training recording {item['file']} changed since training"
    return data, ""


def with_extra(
    train: Any, note: str, split: Mapping[str, Any], task: Any, *, reference: Any,
    options: Mapping[str, Any], run_dir: str | Path | None = None,
) -> tuple[Any, str]:
    """A run's training data for its baselines (``train``, or None with ``note`` saying why)
    joined by the extra training trials its split.json names, so that the baselines are fitted
    on the trials the run trained on; (None, why) when an extra recording is gone or changed."""
    if train is None or not split.get("extra_train"):
        return train, note
    extras, why = stored_extra(split, task, reference=reference, options=options, run_dir=run_dir)
    if why:
        return None, why
    return join_training(train, extras, [e["file"] for e in split["extra_train"]]), ""
