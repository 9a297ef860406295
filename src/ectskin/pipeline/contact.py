"""The reproduction's contact steps: the contact experiment, the contact model, ECT images.

::

    simulate_contact   OUT_DIR/contact.h5                the contact experiment (twin)
    train_contact      OUT_DIR/runs/contact/              ContactNet (quick or paper profile)
    evaluate_contact   OUT_DIR/runs/contact/metrics.json  with its baselines and figures
    ect_images         OUT_DIR/ect/                       training-free ECT images of the
                                                          contact run's test trials

With a given recording (``ReproduceConfig.recording``) the contact model trains on it when its
trials carry finger ground truth; otherwise the contact steps are skipped with a note.
"""

from __future__ import annotations

import logging
from functools import partial
from pathlib import Path
from typing import Any

from ectskin._files import read_json
from ectskin.io import write_recording
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.pipeline.config import CONTACT_RUN, RUNS, ReproduceConfig
from ectskin.pipeline.runner import StepRunner
from ectskin.pipeline.steps import recording_digest, run_settings
from ectskin.twin import simulate_experiment

log = logging.getLogger(__name__)

CONTACT_FILE = "contact.h5"


def contact_data(runner: StepRunner, config: ReproduceConfig) -> tuple[Path, dict[str, Any]] | None:
    """Step "simulate_contact": ``OUT_DIR/contact.h5``; None when a given recording lacks
    ground truth (then the contact steps are skipped)."""
    path = runner.out / CONTACT_FILE
    if config.recording is not None:
        missing = [t.name for t in config.recording.trials if t.missing_ground_truth]
        if missing:
            log.warning(
                "contact: skipped; the given recording has no finger ground truth (trial %r)",
                missing[0],
            )
            return None
        recording = config.recording
        settings = {"source": "given recording", "digest": recording_digest(recording)}

        def make() -> None:
            write_recording(recording, path, overwrite=True)

    else:
        protocol = config.contact_protocol()
        settings = {"source": "ectskin.twin", "protocol": protocol.to_dict()}

        def make() -> None:
            rec = simulate_experiment(protocol, workers=config.workers, progress=config.progress)
            write_recording(rec, path, overwrite=True)

    runner.step("simulate_contact", settings, [path], make)
    return path, settings


def contact_run(
    runner: StepRunner,
    config: ReproduceConfig,
    data_path: Path,
    data_settings: dict[str, Any],
    threads: int | None,
) -> dict[str, Any]:
    """Steps "train_contact" and "evaluate_contact"; returns the run's metrics.json."""
    name = CONTACT_RUN
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
        progress=config.progress,
        threads=threads,
    )
    fit = partial(train_from_recording, task, data_path, run_dir, train_config)
    runner.step(f"train_{name}", settings, [run_dir], fit)
    evaluate = partial(
        evaluate_run,
        run_dir,
        data_path,
        baselines=config.baselines,
        figures=True,
        seed=config.seed,
        out=run_dir,
        overwrite=True,
        figure_format=config.figure_format,
        dpi=config.dpi,
    )
    eval_settings = {**settings, "baselines": config.baselines, **config.figure_settings}
    runner.step(f"evaluate_{name}", eval_settings, [run_dir / "metrics.json"], evaluate)
    return read_json(run_dir / "metrics.json", "contact run metrics")
