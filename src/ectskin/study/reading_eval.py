"""One cell of the reading ablation (:mod:`ectskin.study.reading`): simulate a row's protocol,
split it, train the paper's TouchMLP with two recipes, fit the touch baselines, score them all.

What :func:`measure` does for a row and a seed, as the reproduction does it
(:mod:`ectskin.pipeline.steps`, runs ``touch`` and ``touch_robust``):

1. **simulate** the row's protocol (:func:`ectskin.twin.simulate_experiment`, ``workers``
   processes; the recording does not depend on their number) into ``WORK/data.h5``; a data file
   already there of the same protocol (an interrupted cell) is read instead (``simulate.json``
   keeps its time);
2. **trial-exclusive rows**: :func:`ectskin.learn.train.train_from_recording` splits the trials
   125 / 32 / 32, stratified by region, with the split seed = the seed (the reproduction's
   split), and trains the TouchMLP under the ``quick`` profile (what ``ectskin demo`` trains its
   ``touch`` run with: the paper's recipe, plain cross-entropy and the weights of the lowest
   validation loss, over 30 epochs of batch 256, the learning rate divided by 1.2 every 5
   epochs) and under the ``robust`` profile; :func:`ectskin.learn.evaluate.evaluate_run` scores
   each on the test trials, the first with the touch baselines fit on the same training trials;
3. **the frame-level diagnostic** (row ``split="frame"``): the calibrated frames of all trials
   (:func:`ectskin.learn.data.touch.touch_dataset`) are dealt at random, with the same seed,
   into train / val / test in the proportions 125 : 32 : 32: consecutive frames of one trial
   land in all three, so the test frames' trials are seen in training (a leak, on purpose). The
   same trainings and baselines run on these parts (:func:`ectskin.learn.train.train`,
   :class:`ectskin.learn.predict.touch.TouchPredictor`,
   :func:`ectskin.learn.baselines.touch.touch_baselines`).

Training runs on one torch thread (the demo's choice on this kind of machine: results depend on
the thread count), so a cell's numbers are deterministic.
"""

from __future__ import annotations

import logging
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._files import read_json, to_jsonable, write_json_atomic
from ectskin.twin.protocol import Protocol

log = logging.getLogger(__name__)

#: the profile of the paper's recipe here: the demo's ``touch`` run (ectskin.learn.profiles)
PAPER_PROFILE = "quick"
#: the profile of the robust recipe (the demo's ``touch_robust`` run)
ROBUST_PROFILE = "robust"
#: torch CPU threads of the trainings
THREADS = 1
#: splits a row may use
SPLITS = ("trial", "frame")
DATA_FILE = "data.h5"
SIMULATE_FILE = "simulate.json"


def simulate_into(protocol: Protocol, work: Path, workers: int) -> tuple[Path, float]:
    """``work/data.h5`` of ``protocol`` and the seconds its simulation took (reused, with its
    recorded time, when a finished one of the same protocol is there)."""
    from ectskin.io import read_recording, write_recording
    from ectskin.twin import simulate_experiment

    path, note = work / DATA_FILE, work / SIMULATE_FILE
    want = to_jsonable(protocol.to_dict())
    if path.exists() and note.exists():
        done = read_json(note, "simulation note")
        if isinstance(done, dict) and done.get("protocol") == want:
            stored = read_recording(path).meta.get("protocol")
            if to_jsonable(stored) == want:
                log.info("reading ablation: reusing %s", path)
                return path, float(done["seconds"])
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rec = simulate_experiment(protocol, workers=workers, progress=False)
    seconds = time.perf_counter() - t0
    write_recording(rec, path, overwrite=True)
    write_json_atomic(note, {"protocol": want, "seconds": seconds})
    return path, seconds


def _train_config(profile: str, seed: int) -> Any:
    from ectskin.learn.profiles import TrainConfig

    return TrainConfig(
        profile=profile, seed=seed, resume=False, progress=False, threads=THREADS
    )


def profile_reference(profile: str) -> str:
    """The Eq. 2 reference a touch run of ``profile`` calibrates its frames with, as
    :func:`ectskin.learn.train.train_from_recording` chooses it ("auto": the rest state; a
    profile may follow the inflation where :class:`~ectskin.learn.profiles.TrainConfig` has
    ``reference_for``)."""
    config = _train_config(profile, 0)
    choose = getattr(config, "reference_for", None)
    return "auto" if choose is None else str(choose("touch"))


def recipes() -> dict[str, Any]:
    """The two recipes' settings as the cells train them (profile, its training settings and the
    calibration reference): part of a cell's settings, so a changed profile reruns the cells."""
    from dataclasses import asdict

    from ectskin.learn.profiles import profile_settings

    return {
        key: {
            "profile": profile,
            "settings": asdict(profile_settings("touch", profile)),
            "reference": profile_reference(profile),
        }
        for key, profile in (("paper", PAPER_PROFILE), ("robust", ROBUST_PROFILE))
    }


def _best_baseline(baselines: dict[str, Any]) -> dict[str, Any]:
    """The strongest baseline: {"name", "accuracy"} (the first of equals in the given order)."""
    name = max(baselines, key=lambda k: float(baselines[k]))
    return {"name": name, "accuracy": float(baselines[name])}


def _trial_split(data_path: Path, work: Path, seed: int) -> dict[str, Any]:
    """Train and score both recipes and the baselines on the reproduction's trial split."""
    from ectskin.learn.evaluate import evaluate_run
    from ectskin.learn.train import train_from_recording

    out: dict[str, Any] = {}
    for key, profile in (("paper", PAPER_PROFILE), ("robust", ROBUST_PROFILE)):
        run_dir = work / "runs" / key
        t0 = time.perf_counter()
        summary = train_from_recording("touch", data_path, run_dir, _train_config(profile, seed))
        train_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        metrics = evaluate_run(
            run_dir, data_path, baselines=key == "paper", figures=False, write=False, seed=seed
        )["touch"]
        out[key] = {
            "profile": profile,
            "accuracy": float(metrics["accuracy"]),
            "n_misclassified": int(metrics["n_misclassified"]),
            "n_test_frames": int(metrics["n_test_frames"]),
            "best_epoch": int(summary["best_epoch"]),
            "epochs": int(summary["epochs"]),
            "recipe": summary.get("recipe"),
            "train_seconds": train_s,
            "evaluate_seconds": time.perf_counter() - t0,
        }
        if key == "paper":
            out["baselines"] = {
                k: float(v["accuracy"]) for k, v in metrics["baselines"].items()
            }
            out["split"] = {
                "kind": "trial",
                "n_train_frames": int(summary["n_train"]),
                "n_val_frames": int(summary["n_val"]),
                "n_test_frames": int(metrics["n_test_frames"]),
            }
    return out


def frame_split(n_frames: int, seed: int, counts: tuple[float, float, float]) -> dict[str, Any]:
    """A random train / val / test split of ``n_frames`` frames in the proportions ``counts``,
    drawn with ``seed``: :func:`ectskin.learn.splits.split_groups` with every frame its own
    group (sorted index arrays)."""
    from ectskin.learn.splits import split_groups

    return split_groups(n_frames, counts, seed=seed)


def _frame_split(data_path: Path, work: Path, seed: int) -> dict[str, Any]:
    """The diagnostic: both recipes and the baselines on a frame-level random split."""
    from ectskin.io import read_recording
    from ectskin.learn.baselines.touch import touch_baselines
    from ectskin.learn.data.touch import touch_dataset
    from ectskin.learn.predict.touch import TouchPredictor
    from ectskin.learn.splits import TOUCH_SPLIT
    from ectskin.learn.train import train

    rec = read_recording(data_path)
    out: dict[str, Any] = {}
    for key, profile in (("paper", PAPER_PROFILE), ("robust", ROBUST_PROFILE)):
        # calibrated as a trial-split run of the profile is (train_from_recording)
        reference = profile_reference(profile)
        data = touch_dataset(rec, reference=reference)
        ids = frame_split(data.n_samples, seed, TOUCH_SPLIT)
        parts = {k: data.take(v) for k, v in ids.items()}
        test = parts["test"]
        run_dir = work / "runs" / key
        t0 = time.perf_counter()
        summary = train("touch", parts["train"], parts["val"], run_dir, _train_config(profile, seed))
        train_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        pred = np.asarray(TouchPredictor.from_run(run_dir).classify(test.x))
        wrong = int(np.count_nonzero(pred != test.y))
        out[key] = {
            "profile": profile,
            "accuracy": 1.0 - wrong / test.n_samples,
            "n_misclassified": wrong,
            "n_test_frames": int(test.n_samples),
            "best_epoch": int(summary["best_epoch"]),
            "epochs": int(summary["epochs"]),
            "recipe": summary.get("recipe"),
            "train_seconds": train_s,
            "evaluate_seconds": time.perf_counter() - t0,
        }
        if key == "paper":  # the baselines on the paper recipe's frames, as evaluate_run fits them
            t0 = time.perf_counter()
            base = touch_baselines(parts["train"], test, seed=seed)
            out[key]["evaluate_seconds"] += time.perf_counter() - t0
            out["baselines"] = {k: float(r.accuracy) for k, r in base.items()}
            out["split"] = {
                "kind": "frame",
                **{f"n_{k}_frames": int(v.size) for k, v in ids.items()},
            }
    return out



def measure(
    protocol: Protocol, split: str, work: Path, workers: int, *, keep_data: bool = False
) -> dict[str, Any]:
    """The numbers of one cell (module docstring) for ``protocol`` (its seed is the cell's)
    and ``split`` ("trial" or "frame"), working in ``work`` (removed afterwards, but for its
    data file with ``keep_data``)."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    seed = protocol.seed
    data_path, sim_s = simulate_into(protocol, work, workers)
    runs = work / "runs"
    if runs.exists():
        shutil.rmtree(runs)
    body = (_trial_split if split == "trial" else _frame_split)(data_path, work, seed)
    body["best_baseline"] = _best_baseline(body["baselines"])
    body["seconds"] = {
        "simulate": sim_s,
        "train_paper": body["paper"]["train_seconds"],
        "train_robust": body["robust"]["train_seconds"],
        "evaluate": body["paper"]["evaluate_seconds"] + body["robust"]["evaluate_seconds"],
    }
    shutil.rmtree(runs, ignore_errors=True)
    if not keep_data:
        shutil.rmtree(work, ignore_errors=True)
    return body
