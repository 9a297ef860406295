"""Reproduce the paper end to end: simulate → characterise → train → evaluate → report.

:func:`reproduce` is what ``ectskin reproduce OUT_DIR`` and ``ectskin demo`` run. It writes::

    data.h5                       the simulated experiment (paper §3 protocol)
    coverage.h5                   the twin's coverage trials (every region in every state) that
                                  the robust run adds to its training split (ectskin.twin.coverage)
    contact.h5                    the contact experiment (ours, see ectskin.pipeline.config)
    characterize/                 Fig. 3, Fig. 4 and characterize.json of the twin
    runs/<run>/                   one training per run of :data:`ectskin.pipeline.config.RUNS`
                                  (model.pt, metrics.csv, split.json, metrics.json, figures)
    bound/                        the physical limit of the contact states (bound.json, figures;
                                  ectskin.pipeline.bound)
    inversion/metrics.json        the training-free inversion on the contact run's test frames
                                  (ectskin.pipeline.inversion)
    figures/                      copies of the figures shown in the report
    metrics.json, report.md, report.html
    reproduce.json                what each step was run with, whether it finished, its time

Nothing is overwritten silently: finished steps are reused, interrupted ones resumed, and results
made with other settings are refused unless ``force`` (``--overwrite``;
:mod:`ectskin.pipeline.runner`). The evaluations' figures are PNG unless ``figure_format`` says
PDF or SVG; the twin's Fig. 3/4 are PNG.

Profiles: ``quick`` trains with the ``quick`` settings of :mod:`ectskin.learn.train` (the
ablations for :data:`~ectskin.pipeline.config.QUICK_ABLATION_EPOCHS` epochs), ``paper`` with the
paper's (meant for a GPU). Both simulate the paper's protocol (189 trials of 30 s) unless a
protocol is given, and both also train the TouchMLP with the ``robust`` profile on the same split
(``touch.robust`` in metrics.json), its training split joined by the twin's coverage trials of the
simulated protocol (``coverage``; validation and test stay the experiment's trials).
"""

from __future__ import annotations

import logging
import shutil
import time
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError, check_type
from ectskin._files import read_json, write_json_atomic
from ectskin.inversion.fit import FINGER_SCALE_SD
from ectskin.io.hdf5 import read_recording
from ectskin.learn.threads import torch_threads
from ectskin.pipeline.bound import bound_step
from ectskin.pipeline.config import ReproduceConfig
from ectskin.pipeline.contact import (
    contact_data,
    contact_run,
    ect_block,
    ect_images,
    handling_off,
    n_touch_points,
)
from ectskin.pipeline.field import contact_fields, physics_field_specs
from ectskin.pipeline.inversion import inversion_step
from ectskin.pipeline.metrics import combine_metrics, copy_figures, handling_block
from ectskin.pipeline.runner import StepRunner
from ectskin.pipeline.steps import (
    characterise,
    coverage_data,
    evaluate_runs,
    simulate_or_load,
    train_runs,
)
from ectskin.report import write_report
from ectskin.viz import figure_file

log = logging.getLogger(__name__)


def reproduce(config: ReproduceConfig) -> dict[str, Any]:
    """Run the whole reproduction into ``config.out_dir``; return the metrics written to
    ``metrics.json`` (exactly as saved).

    Training and evaluation run with the torch CPU threads that ``config.threads`` resolves to
    (:func:`ectskin.learn.threads.torch_threads`); the previous setting is restored afterwards.
    """
    check_type("config", config, ReproduceConfig)
    out = config.out_dir
    if out.exists() and not out.is_dir():
        raise EctskinError(f"output folder {out} exists and is not a folder")
    with torch_threads(config.threads) as n_threads:
        return _run(config, n_threads)


#: the inversion's two-finger model in the reproduction: the coupled conductors (two grounded
#: fingers screen each other: a finger hovering 10 mm over another's press leaves 0.65-0.85 of
#: its signal, twin/field_response.py), with fingertips kept two radii apart (Inversion's
#: ``min_separation_mm``); BENCHMARKS.md has both models on seeds 0-2
REPRODUCTION_TWO_FINGERS = "coupled"


def _physics_steps(
    runner: StepRunner, config: ReproduceConfig, found: tuple[Path, dict[str, Any]],
    contact: dict[str, Any],
) -> tuple[dict[str, Any] | None, dict[str, Any] | None]:
    """Steps "bound" and "inversion" on the contact experiment's response fields (those the
    contact step built, read back from the cache; with ``field_states="all"`` also those of the
    paper's other states, built here); (None, None) when the contact experiment is not read from
    fields (a given recording, or ``contact_response="solve"``)."""
    if config.recording is not None or config.contact_response != "field":
        log.info("bound, inversion: skipped (the contact data were not made from response fields)")
        return None, None
    t0 = time.perf_counter()
    fields = contact_fields(config, specs=physics_field_specs(config))  # built where missing
    runner.timings["contact_fields_load"] = time.perf_counter() - t0
    if not fields:
        return None, None
    bound = bound_step(runner, config, fields, found, push_columns=config.bound_push_columns,
                       train_trials=True)
    # the skin's own untouched readout, people's finger sizes and the press check: chosen on the
    # validation trials of the contact experiment (docs/inversion.md); so is the contact model
    # of the states with a field (choice: the run's model, its baselines, inversion, hybrid)
    inversion = inversion_step(runner, config, fields, found, contact, untouched="auto",
                               finger_scale_sd=FINGER_SCALE_SD, press_check=True, choice=True,
                               two_fingers=REPRODUCTION_TWO_FINGERS, finger=config.inversion_finger,
                               train_trials=True)
    return bound, inversion


def _run(config: ReproduceConfig, threads: int) -> dict[str, Any]:
    out = config.out_dir
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    runner = StepRunner(out, config.force)

    data_path, data_settings = simulate_or_load(runner, config)
    if config.characterize and config.recording is None:
        characterise(runner, config)
    coverage_data(runner, config)
    train_runs(runner, config, data_path, data_settings, threads)
    results = evaluate_runs(runner, config, data_path, data_settings)
    contact = ect = off = found = bound = inversion = None
    if config.contact:
        found = contact_data(runner, config, data_settings)
        if found is not None:
            contact = contact_run(runner, config, *found, threads)
            off = handling_off(runner, config, *found)
            ect = ect_images(runner, config, *found)
            bound, inversion = _physics_steps(runner, config, found, contact)

    metrics = combine_metrics(
        results,
        runner,
        profile=config.profile,
        seed=config.seed,
        protocol=config.simulation_protocol(),
        data_settings=data_settings,
        data_path=data_path,
        contact=contact,
        bound=bound,
        inversion=inversion,
    )
    if found is not None and "contact" in metrics:
        metrics["contact"]["n_touch_points"] = n_touch_points(read_recording(found[0]))
    if off is not None:
        metrics["contact"]["handling_off"] = handling_block(off)
    if ect is not None:
        metrics["ect_image"] = ect_block(ect, contact)
    if config.command:
        metrics["command"] = config.command
    runs = config.run_names + (("contact",) if contact is not None else ())
    figures = copy_figures(out, runs, config.figure_format)
    ect_figure = out / "ect" / figure_file("ect_images", config.figure_format)
    if ect is not None and ect_figure.is_file():
        dst = out / "figures" / ect_figure.name
        shutil.copyfile(ect_figure, dst)
        figures[
            "ECT images (Tikhonov, no training) of test touches: true point (circle), located "
            "peak (cross)"
        ] = dst.relative_to(out).as_posix()
    metrics["figures"] = dict(figures)
    metrics["timings_s"]["total"] = time.perf_counter() - t_start
    write_json_atomic(out / "metrics.json", metrics)
    metrics = read_json(out / "metrics.json", "metrics")  # return exactly what was saved
    write_report(out, metrics, figures)
    if runner.reused:
        log.info("reused finished steps: %s", ", ".join(runner.reused))
    log.info(
        "reproduction written to %s (report.md, report.html, metrics.json) in %.1f s",
        out,
        metrics["timings_s"]["total"],
    )
    return metrics
