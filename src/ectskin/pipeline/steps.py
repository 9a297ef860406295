"""The steps of a reproduction: data, characterisation, training, evaluation.

Each function runs one kind of step through a :class:`~ectskin.pipeline.runner.StepRunner`, with
the settings that decide whether an earlier result in the output folder can be reused::

    simulate        OUT_DIR/data.h5              twin (protocol) or the given recording
    simulate_coverage OUT_DIR/coverage.h5        the twin's coverage trials of the protocol
                                                 (training split of the robust run only)
    characterize    OUT_DIR/characterize/        Fig. 3, Fig. 4, characterize.json of the twin
    train_<run>     OUT_DIR/runs/<run>/          model.pt, last.pt, metrics.csv, split.json ...
    evaluate_<run>  OUT_DIR/runs/<run>/metrics.json (+ figures; baselines for touch and track)
"""

from __future__ import annotations

import hashlib
import logging
import os
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin._files import read_json
from ectskin.io import Recording, read_recording, write_recording
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.profiles import RECIPE_FIELDS, profile_settings
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.pipeline.config import RUNS, ReproduceConfig
from ectskin.pipeline.runner import Job, StepRunner, digest, plain, settings_diff
from ectskin.twin import simulate_experiment
from ectskin.twin.characterize import characterize as characterize_twin

log = logging.getLogger(__name__)

DATA_FILE = "data.h5"
#: the twin's coverage trials (ectskin.twin.coverage), added to the robust run's training split
COVERAGE_FILE = "coverage.h5"
#: the runs evaluated against the baselines, each on its own calibrated inputs (the touch runs
#: may differ in their Eq. 2 reference; the ablations are compared to ``track``)
MAIN_RUNS = ("touch", "touch_robust", "track")


def recording_digest(recording: Recording) -> str:
    """A short hash of a recording's trial names and capacitance, to recognise it again."""
    h = hashlib.blake2b(digest_size=8)
    for t in recording.trials:
        h.update(t.name.encode())
        h.update(np.ascontiguousarray(t.capacitance).tobytes())
    return h.hexdigest()


def _check_adoptable(path: Path, protocol_settings: dict[str, Any]) -> None:
    """Raise unless ``path`` (a data.h5 with no record in the state file) holds a recording of
    the protocol ``protocol_settings``."""
    try:
        found = plain(read_recording(path).meta.get("protocol"))
    except EctskinError as exc:
        raise EctskinError(
            f"{path} exists but is not a readable recording of this protocol ({exc}); "
            f"pass --overwrite to simulate again, or use another output folder"
        ) from None
    want = plain(protocol_settings)
    if found != want:
        detail = settings_diff(found, want) if isinstance(found, dict) else "no protocol stored"
        raise EctskinError(
            f"{path} holds a recording of another protocol ({detail}); pass --overwrite to "
            f"simulate again, or use another output folder"
        )


def simulate_or_load(runner: StepRunner, config: ReproduceConfig) -> tuple[Path, dict[str, Any]]:
    """Step "simulate": ``OUT_DIR/data.h5`` from the twin, or from ``config.recording``.

    A data.h5 found without a record in the state file is adopted when it holds the same
    protocol (and refused otherwise, unless ``force``). Returns (path, the step's settings).
    """
    path = runner.out / DATA_FILE
    recording = config.recording
    if recording is not None:
        settings: dict[str, Any] = {
            "source": "given recording",
            "digest": recording_digest(recording),
            "n_trials": recording.n_trials,
        }

        def make() -> None:
            write_recording(recording, path, overwrite=True)

        runner.step("simulate", settings, [path], make)
    else:
        protocol = config.simulation_protocol()
        assert protocol is not None  # None only when a recording is given
        settings = _twin_step(runner, config, "simulate", protocol, path)
    return path, settings


def _twin_step(
    runner: StepRunner, config: ReproduceConfig, name: str, protocol: Any, path: Path
) -> dict[str, Any]:
    """Step ``name``: ``path`` holding the twin's simulation of ``protocol``. A file found there
    without a record in the state file is adopted when it holds the same protocol (e.g. made
    with ``ectskin simulate``), refused otherwise (unless ``force``). Returns the settings."""
    settings = {"source": "ectskin.twin", "protocol": protocol.to_dict()}
    if path.exists() and runner.state.settings(name) is None and not runner.force:
        _check_adoptable(path, settings["protocol"])
        log.info("%s: %s holds the same protocol; reusing it", name, path)
        runner.adopt(name, settings)

    def make() -> None:
        rec = simulate_experiment(protocol, workers=config.workers, progress=config.progress)
        write_recording(rec, path, overwrite=True)

    runner.step(name, settings, [path], make)
    return settings


def coverage_settings(config: ReproduceConfig) -> dict[str, Any] | None:
    """The settings of step "simulate_coverage" (None when the config has no coverage trials)."""
    protocol = config.coverage_protocol()
    if protocol is None:
        return None
    return {"source": "ectskin.twin", "protocol": protocol.to_dict()}


def coverage_data(runner: StepRunner, config: ReproduceConfig) -> Path | None:
    """Step "simulate_coverage": ``OUT_DIR/coverage.h5``, the twin's coverage trials of the
    simulated protocol (:meth:`ReproduceConfig.coverage_protocol`) that the robust run adds to
    its training split; None when there are none (no robust run, ``coverage`` off, or a given
    recording). A coverage.h5 found without a record is adopted as data.h5 is."""
    protocol = config.coverage_protocol()
    if protocol is None:
        return None
    path = runner.out / COVERAGE_FILE
    _twin_step(runner, config, "simulate_coverage", protocol, path)
    return path


def characterise(runner: StepRunner, config: ReproduceConfig) -> None:
    """Step "characterize": the twin's §2.2 characterisation into ``OUT_DIR/characterize``."""
    char_dir = runner.out / "characterize"
    runner.step(
        "characterize",
        {"seed": config.seed, **config.figure_settings},
        [char_dir],
        lambda: characterize_twin(
            char_dir, seed=config.seed, figure_format=config.figure_format, dpi=config.dpi
        ),
    )


def run_settings(
    config: ReproduceConfig, name: str, data_settings: dict[str, Any]
) -> dict[str, Any]:
    """The settings a training of run ``name`` depends on (and its evaluation, with
    ``baselines``)."""
    task, window, prior = RUNS[name]
    model: dict[str, Any] = (
        {"model": config.touch_model} if name == "touch" and config.touch_model != "mlp" else {}
    )
    if task == "touch":  # the Eq. 2 reference and the recipe of the run's profile
        profile = config.run_profile(name)
        s = profile_settings(task, profile)
        model["reference"] = TrainConfig(profile=profile).reference_for(task)
        model["recipe"] = {k: getattr(s, k) for k in RECIPE_FIELDS}
        coverage = coverage_settings(config) if name == "touch_robust" else None
        if coverage is not None:  # the twin's coverage trials join its training split
            model["extra_train"] = {"coverage": digest(coverage)}
    return {
        **model,
        "data": digest(data_settings),
        "task": task,
        "window": window,
        "prior": prior,
        "profile": config.run_profile(name),
        "seed": config.seed,
        "epochs": config.epochs_for(name),
    }


def train_runs(
    runner: StepRunner,
    config: ReproduceConfig,
    data_path: Path,
    data_settings: dict[str, Any],
    threads: int | None,
) -> dict[str, dict[str, Any]]:
    """Steps "train_<run>" for every run of ``config``, with ``threads`` torch CPU threads each,
    side by side in as many processes as the cores allow (:func:`training_processes`; the runs
    are independent and each is deterministic, so the results do not depend on it). Returns
    {run: training summary} of the runs trained now (reused ones are left out)."""
    processes = training_processes(config, threads)
    # the tracking runs first: they take longest, so the short touch runs fill in after them
    names = sorted(config.run_names, key=lambda n: RUNS[n][0] != "track")
    # progress bars of two processes would mix: none when runs train side by side
    jobs = [
        train_job(runner, config, n, data_path, data_settings, threads, processes == 1)
        for n in names
    ]
    done = runner.steps(jobs, processes)
    return {name.removeprefix("train_"): s for name, s in done.items() if s is not None}


def train_job(
    runner: StepRunner,
    config: ReproduceConfig,
    name: str,
    data_path: Path,
    data_settings: dict[str, Any],
    threads: int | None,
    progress: bool = True,
) -> Job:
    """Step "train_<name>": run ``name`` of :data:`RUNS` trained on ``data_path`` into
    ``OUT_DIR/runs/<name>`` with the run's settings (:func:`run_settings`), resuming an
    interrupted training; ``progress`` and ``config.progress`` both to show a bar."""
    task, window, prior = RUNS[name]
    settings = run_settings(config, name, data_settings)
    run_dir = runner.out / "runs" / name
    train_config = TrainConfig(
        profile=settings["profile"],
        seed=config.seed,
        epochs=settings["epochs"],
        window=window,
        prior=prior,
        resume=True,
        device=config.device,
        progress=config.progress and progress,
        threads=threads,
        model=settings.get("model", "mlp"),
        extra_train=(str(runner.out / COVERAGE_FILE),) if "extra_train" in settings else (),
    )
    log.info(
        "train %s: %s, window %d, prior %s, profile %s", name, *RUNS[name], settings["profile"]
    )
    fit = partial(train_from_recording, task, data_path, run_dir, train_config)
    return Job(f"train_{name}", settings, [run_dir], fit)


def training_processes(config: ReproduceConfig, threads: int | None) -> int:
    """How many runs train at once: the cores (``config.workers``, default all) over the torch
    threads each uses; 1 on a GPU (``config.device``, or CUDA found when it is None)."""
    import torch

    gpu = config.device not in (None, "cpu") or (
        config.device is None and torch.cuda.is_available()
    )
    if gpu:
        return 1
    cores = config.workers or os.cpu_count() or 1
    return max(1, cores // max(threads or 1, 1))


def evaluate_runs(
    runner: StepRunner,
    config: ReproduceConfig,
    data_path: Path,
    data_settings: dict[str, Any],
) -> dict[str, dict[str, Any]]:
    """Steps "evaluate_<run>": each run's ``metrics.json`` on its test split (baselines on the
    same split for the two main runs), with its figures in ``config.figure_format``. Returns
    {run: its metrics.json}. The runner decides what may be replaced (an interrupted step, or
    ``force``), so the evaluation itself overwrites; it writes into the run folder under the
    plain names even when the folder was moved (``split.json`` then names the old data path)."""
    results: dict[str, dict[str, Any]] = {}
    for name in config.run_names:
        run_dir = runner.out / "runs" / name
        with_baselines = config.baselines and name in MAIN_RUNS
        settings = {
            **run_settings(config, name, data_settings),
            "baselines": with_baselines,
            **config.figure_settings,
        }
        evaluate = partial(
            evaluate_run,
            run_dir,
            data_path,
            baselines=with_baselines,
            figures=True,
            seed=config.seed,
            out=run_dir,
            overwrite=True,
            figure_format=config.figure_format,
            dpi=config.dpi,
        )
        runner.step(f"evaluate_{name}", settings, [run_dir / "metrics.json"], evaluate)
        results[name] = read_json(run_dir / "metrics.json", "run metrics")
    return results
