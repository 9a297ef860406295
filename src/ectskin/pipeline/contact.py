"""The reproduction's contact steps: the contact experiment, the contact model, ECT images.

::

    simulate_contact   OUT_DIR/contact.h5                the contact experiment (twin) and
                                                          the paper's trials of data.h5
    train_contact      OUT_DIR/runs/contact/              ContactNet (quick or paper profile)
    evaluate_contact   OUT_DIR/runs/contact/metrics.json  with its baselines and figures
    evaluate_contact_handling_off
                       OUT_DIR/contact_handling_off.h5   the test trials again without the
                       OUT_DIR/runs/contact/handling_off/ hand, and the run evaluated on them
    ect_images         OUT_DIR/ect/                       training-free ECT images of the
                                                          contact run's test trials

With a given recording (``ReproduceConfig.recording``) the contact model trains on it when its
trials carry finger ground truth; otherwise the contact steps are skipped with a note.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin._files import read_json, save_figure_atomic, to_jsonable, write_json_atomic
from ectskin.electrostatics.reconstruct import METHODS
from ectskin.io import Recording, read_recording, write_recording
from ectskin.learn.evaluate import evaluate_run
from ectskin.pipeline.config import CONTACT_RUN, ReproduceConfig
from ectskin.pipeline.field import contact_field_dirs, contact_field_specs, contact_fields
from ectskin.pipeline.runner import StepRunner, digest
from ectskin.pipeline.steps import DATA_FILE, recording_digest, run_settings, train_job
from ectskin.twin import simulate_experiment
from ectskin.twin.ect_metrics import ect_image_metrics
from ectskin.twin.field_response import FIELD_RESPONSE_VERSION
from ectskin.viz import figure_file
from ectskin.viz.ect import plot_ect_images

log = logging.getLogger(__name__)

CONTACT_FILE = "contact.h5"
HANDLING_OFF_FILE = "contact_handling_off.h5"
#: every this many frames in contact is imaged by the ECT step
ECT_FRAME_STEP = 10


def with_paper_trials(paper: Recording, contact: Recording) -> Recording:
    """One recording of the paper's trials (renamed ``paper_<name>``) and the contact
    experiment's (``contact_<name>``), for the contact model: the paper's trials add touch
    points at the regions' centres at all 27 inflation states; the contact experiment adds
    points anywhere, lifts, hover and a second finger."""
    if (
        paper.layout.to_json() != contact.layout.to_json()
        or paper.frame_rate_hz != contact.frame_rate_hz
    ):
        raise EctskinError(
            "the paper's recording and the contact experiment differ in layout or frame rate; "
            "they cannot be trained on together"
        )
    trials = [replace(t, name=f"paper_{t.name}") for t in paper.trials]
    trials += [replace(t, name=f"contact_{t.name}") for t in contact.trials]
    meta = {"protocol": contact.meta.get("protocol"), "paper_protocol": paper.meta.get("protocol")}
    if "manipulator" in contact.meta:  # the body both were simulated on (distances go around it)
        if to_jsonable(paper.meta.get("manipulator")) != to_jsonable(contact.meta["manipulator"]):
            raise EctskinError(
                "the paper's recording and the contact experiment were made on different "
                "manipulators (meta 'manipulator'); they cannot be trained on together"
            )
        meta["manipulator"] = contact.meta["manipulator"]
    return Recording(contact.layout, trials, contact.frame_rate_hz, meta=meta)


def n_touch_points(rec: Recording) -> int | None:
    """How many distinct points (face, u, v) the fingers of ``rec``'s touch trials were placed
    at: the dwell points the twin planned (trial meta ``touch_uv_mm`` with ``surface``, and
    ``second_finger``), to 0.01 mm; None when no trial says (a recording from elsewhere).

    A dwell counts only if the finger touched the skin in it (its equal share of the trial's
    frames holds a frame in contact, when the trial has per-frame contact): a dwell spent
    lifted or hovering placed no finger."""
    points: set[tuple[str, float, float]] = set()
    said = False
    for t in rec.trials:
        dwells = t.meta.get("touch_uv_mm")
        if dwells is None:
            continue
        said = True
        touched = _touched_dwells(t, len(dwells))
        for (u, v), on in zip(dwells, touched):
            if on:
                points.add((str(t.meta.get("surface", "")), round(float(u), 2), round(float(v), 2)))
        second = t.meta.get("second_finger")
        if isinstance(second, dict) and second.get("touch_uv_mm"):
            u, v = second["touch_uv_mm"]
            points.add((str(second.get("surface", "")), round(float(u), 2), round(float(v), 2)))
    return len(points) if said else None


def _touched_dwells(trial, n_dwells: int) -> list[bool]:
    """Per dwell whether the first finger touched the skin in it (all True without per-frame
    contact); the dwells split the frames in equal shares, in order, as the twin plans them."""
    contact = getattr(trial, "contact", None)
    if contact is None or n_dwells == 0:
        return [True] * n_dwells
    first = np.asarray(contact).reshape(len(contact), -1)[:, 0]
    return [bool(first[rows].any()) for rows in np.array_split(np.arange(first.size), n_dwells)]


def _simulate_contact(
    protocol, config: ReproduceConfig, runner: StepRunner | None, trials=None
) -> Recording:
    """The contact experiment (or its ``trials``), with the states' response fields when it
    reads them (built into the cache first; their build time goes to ``runner.timings``
    as ``contact_fields``)."""
    fields = None
    if protocol.response == "field":
        t0 = time.perf_counter()
        contact_fields(config)
        if runner is not None:
            runner.timings["contact_fields"] = time.perf_counter() - t0
        fields = contact_field_dirs(config)
    return simulate_experiment(
        protocol, workers=config.workers, progress=config.progress, trials=trials, fields=fields
    )


def contact_data(
    runner: StepRunner, config: ReproduceConfig, paper_settings: Mapping[str, Any]
) -> tuple[Path, dict[str, Any]] | None:
    """Step "simulate_contact": ``OUT_DIR/contact.h5``, the contact experiment together with
    the paper's trials of ``OUT_DIR/data.h5`` (made with ``paper_settings``,
    :func:`with_paper_trials`); None when a given recording lacks ground truth (then the
    contact steps are skipped). A contact experiment read from response fields builds the
    missing ones into the field cache first (:func:`ectskin.pipeline.field.contact_fields`;
    the build's seconds are ``timings["contact_fields"]``, part of the step's)."""
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
        settings: dict[str, Any] = {
            "source": "given recording",
            "digest": recording_digest(recording),
        }

        def make() -> None:
            write_recording(recording, path, overwrite=True)

    else:
        protocol = config.contact_protocol()
        assert protocol is not None  # None only when a recording is given
        paper_path = runner.out / DATA_FILE
        settings = {
            "source": "ectskin.twin",
            "protocol": protocol.to_dict(),
            "with": {"file": DATA_FILE, "data": digest(paper_settings)},
        }
        if protocol.response == "field":
            settings["fields"] = [s.key() for s in contact_field_specs(config)]
            settings["field_response"] = FIELD_RESPONSE_VERSION

        def make() -> None:
            rec = _simulate_contact(protocol, config, runner)
            write_recording(
                with_paper_trials(read_recording(paper_path), rec), path, overwrite=True
            )

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
    job = train_job(runner, config, name, data_path, data_settings, threads)
    runner.step(job.name, job.settings, job.outputs, job.fn)
    settings, run_dir = job.settings, job.outputs[0]
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


def handling_off(
    runner: StepRunner, config: ReproduceConfig, data_path: Path, data_settings: dict[str, Any]
) -> dict[str, Any] | None:
    """Step "evaluate_contact_handling_off": the contact run's test trials simulated again with
    the experimenter's hand off (``Protocol.push_max_n = 0``; every other draw of a trial is the
    same, see :func:`ectskin.twin.human.hand_push`), put in place of their hand-on versions in a
    copy of contact.h5 (``OUT_DIR/contact_handling_off.h5``; training and validation trials
    unchanged), and the run and its baselines evaluated on that test split
    (``OUT_DIR/runs/contact/handling_off/metrics.json``). The model trained with the hand on
    throughout; the hand-on numbers of the same test trials are the run's own metrics.

    Returns that metrics.json, or None with a given recording (it cannot be simulated again).
    """
    if config.recording is not None:
        return None
    run_dir = runner.out / "runs" / CONTACT_RUN
    split = read_json(run_dir / "split.json", "contact run split")
    test = list(split.get("test") or [])
    path = runner.out / HANDLING_OFF_FILE
    out_dir = run_dir / "handling_off"
    settings = {
        "data": digest(data_settings),
        "run": digest(run_settings(config, CONTACT_RUN, data_settings)),
        "test_trials": test,
        "baselines": config.baselines,
        "seed": config.seed,
    }
    paper, contact = config.simulation_protocol(), config.contact_protocol()
    assert paper is not None and contact is not None  # None only when a recording is given
    sources = (("paper_", paper), ("contact_", contact))

    def make() -> None:
        rec = read_recording(data_path)
        off: dict[str, Any] = {}
        for prefix, protocol in sources:
            names = [n.removeprefix(prefix) for n in test if n.startswith(prefix)]
            if not names:
                continue
            sim = _simulate_contact(replace(protocol, push_max_n=0.0), config, None, names)
            off.update({prefix + t.name: replace(t, name=prefix + t.name) for t in sim.trials})
        trials = [off.get(t.name, t) for t in rec.trials]
        meta = {**rec.meta, "handling_off_trials": sorted(off)}
        write_recording(
            Recording(rec.layout, trials, rec.frame_rate_hz, meta=meta), path, overwrite=True
        )
        evaluate_run(
            run_dir,
            path,
            baselines=config.baselines,
            figures=False,
            seed=config.seed,
            out=out_dir,
            overwrite=True,
        )

    runner.step("evaluate_contact_handling_off", settings, [path, out_dir], make)
    return read_json(out_dir / "metrics.json", "contact metrics with the hand off")


def ect_images(
    runner: StepRunner, config: ReproduceConfig, data_path: Path, data_settings: dict[str, Any]
) -> dict[str, Any]:
    """Step "ect_images": training-free ECT images of the contact run's test trials
    (:func:`ectskin.twin.ect_metrics.ect_image_metrics`, every 10th frame in contact) into
    ``OUT_DIR/ect/metrics.json`` and a figure of a few touches beside the truth. Returns the
    metrics (without the image arrays)."""
    out_dir = runner.out / "ect"
    split = read_json(runner.out / "runs" / CONTACT_RUN / "split.json", "contact run split")
    test = list(split.get("test") or [])
    settings = {"data": digest(data_settings), "test_trials": test, **config.figure_settings}

    def make() -> None:
        rec = read_recording(data_path)
        result = ect_image_metrics(rec, trials=test, frame_step=ECT_FRAME_STEP)
        examples = result.pop("examples")
        grid = result["grid"]
        out_dir.mkdir(parents=True, exist_ok=True)
        if examples:
            fig = plot_ect_images(examples, grid["faces"], grid["extents"])
            save_figure_atomic(
                fig, out_dir / figure_file("ect_images", config.figure_format), dpi=config.dpi
            )
        write_json_atomic(out_dir / "metrics.json", result)

    runner.step("ect_images", settings, [out_dir], make)
    return read_json(out_dir / "metrics.json", "ECT image metrics")


def ect_block(result: Mapping[str, Any], contact: Mapping[str, Any] | None) -> dict[str, Any]:
    """metrics.json's ``ect_image``: the default method's errors on top, every method beside
    them, the learned contact model's error for comparison, and the timing."""
    methods = {m: result[m] for m in METHODS if m in result}
    best = result.get("settings", {}).get("method", "tikhonov")
    top = methods.get(best, {})
    learned = (contact or {}).get("contact", {}).get("loc_mm_mean")
    timing = result.get("timing") or {}
    jac = list((timing.get("jacobian_s") or {}).values())
    return {
        "method": best,
        "loc_mm_mean": top.get("loc_mm_mean"),
        "loc_mm_median": top.get("loc_mm_median"),
        "loc_mm_p90": top.get("loc_mm_p90"),
        "face_accuracy": top.get("face_accuracy"),
        "methods": methods,
        "learned_loc_mm_mean": learned,
        "ratio_to_learned": (
            top["loc_mm_mean"] / learned if learned and top.get("loc_mm_mean") is not None else None
        ),
        "timing": {
            "jacobian_s_per_state": (sum(jac) / len(jac)) if jac else None,
            "reconstruct_us_per_frame": timing.get("reconstruct_us_per_frame"),
        },
        "settings": result.get("settings"),
    }
