"""Reproduce the paper end to end: simulate → characterise → train → evaluate → report.

:func:`reproduce` is what ``ectskin reproduce OUT_DIR`` and ``ectskin demo`` run. Each step
writes its results into ``OUT_DIR``::

    data.h5                       the simulated experiment (paper §3 protocol)
    characterize/                 Fig. 3, Fig. 4 and characterize.json of the twin
    runs/touch/                   TouchMLP run (model.pt, metrics.csv, split.json, metrics.json, Fig. 7)
    runs/touch_robust/            the same TouchMLP, ``robust`` training profile (ours), same split
    runs/track/                   C2DT run (prior knowledge, 10 frames; Fig. 9, Fig. 10)
    runs/track_no_prior/          ablation: absolute calibration, no initial coordinates
    runs/track_window_1/          ablation: 1 frame instead of 10
    figures/                      copies of the figures shown in the report
    metrics.json, report.md, report.html
    reproduce.json                what each step was run with, whether it finished, its time

Nothing is overwritten silently. A step that finished with the same settings before is reused
(and listed under ``reused`` in ``metrics.json``); an interrupted training resumes from its
``last.pt``; a step whose earlier results were produced with *other* settings (another seed,
profile, protocol...) is refused with an error unless ``force=True``, which redoes it.

Profiles: ``quick`` trains with the ``quick`` settings of :mod:`ectskin.learn.train` (the demo
fits in ~10 minutes on a 2-core laptop; the ablations train for ``QUICK_ABLATION_EPOCHS``
epochs), ``paper`` with the paper's (100 / 150 epochs; hours on a CPU, meant for a GPU). Both
simulate the paper's protocol (189 trials of 30 s) unless a protocol is given. Beside the
paper-recipe TouchMLP, both also train the same network with the ``robust`` profile of
:mod:`ectskin.learn.train` (20 epochs; ~10-20 s on one core for the paper's protocol) on the same
split, evaluated on the same test trials and reported as ``touch.robust`` in metrics.json.
"""

from __future__ import annotations

import hashlib
import json
import logging
import shutil
import time
from collections.abc import Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ectskin import __version__
from ectskin._check import EctskinError, check_option
from ectskin.learn.evaluate import read_json, write_json_atomic

log = logging.getLogger(__name__)

PROFILES = ("quick", "paper")
STATE_FILE = "reproduce.json"
STATE_FORMAT = "ectskin.reproduce"

#: run name → (task, window, prior). "touch" and "track" are the paper's models, "touch_robust"
#: the TouchMLP trained with the robust recipe (:data:`RUN_PROFILES`), the rest ablations.
RUNS: dict[str, tuple[str, int, bool]] = {
    "touch": ("touch", 10, True),
    "touch_robust": ("touch", 10, True),
    "track": ("track", 10, True),
    "track_no_prior": ("track", 10, False),
    "track_window_1": ("track", 1, True),
}
#: ablation key in metrics.json → run name
ABLATIONS = {"no_prior": "track_no_prior", "window_1": "track_window_1"}
#: runs trained with a fixed profile of ectskin.learn.train instead of reproduce's ``profile``
RUN_PROFILES = {"touch_robust": "robust"}
#: keys of the robust run's touch metrics copied into metrics.json under ``touch.robust``
ROBUST_KEYS = (
    "accuracy",
    "n_test_frames",
    "n_misclassified",
    "misclassified",
    "n_misclassified_adjacent",
    "all_adjacent",
    "confusions",
    "per_class_accuracy",
    "per_trial",
    "worst_trial",
    "training",
    "split",
)
#: epochs of the ablation trainings under the quick profile (the main runs use the profile's)
QUICK_ABLATION_EPOCHS = 12

#: figures copied into OUT_DIR/figures and shown in the report: (run, file, caption, copy's name)
REPORT_FIGURES = (
    (
        "touch",
        "fig7_confusion.png",
        "Fig. 7: touch confusion map of the test set (TouchMLP)",
        "fig7_confusion.png",
    ),
    (
        "touch_robust",
        "fig7_confusion.png",
        "Fig. 7, robust recipe (ours): touch confusion map of the same test set (TouchMLP)",
        "fig7_confusion_robust.png",
    ),
    (
        "track",
        "fig9_tracking.png",
        "Fig. 9: tracking examples, estimated (red) vs true (blue) markers (C2DT)",
        "fig9_tracking.png",
    ),
    (
        "track",
        "fig10_trajectory.png",
        "Fig. 10: one marker's trajectory over a test trial (C2DT)",
        "fig10_trajectory.png",
    ),
    (
        "touch",
        "learning_curves.png",
        "TouchMLP training and validation loss",
        "touch_learning_curves.png",
    ),
    (
        "touch_robust",
        "learning_curves.png",
        "TouchMLP, robust recipe: training (augmented) and validation loss",
        "touch_robust_learning_curves.png",
    ),
    (
        "track",
        "learning_curves.png",
        "C2DT training and validation loss",
        "track_learning_curves.png",
    ),
)


def _plain(obj: Any) -> Any:
    """``obj`` as plain JSON values (tuples → lists ...), so settings compare equal to saved ones."""
    return json.loads(json.dumps(obj, sort_keys=True, default=str))


def _digest(obj: Any) -> str:
    return hashlib.blake2b(
        json.dumps(obj, sort_keys=True, default=str).encode(), digest_size=8
    ).hexdigest()


def _flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(d, Mapping):
        return {prefix or "value": d}
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        out.update(_flatten(v, key) if isinstance(v, Mapping) else {key: v})
    return out


def _diff(old: Any, new: Any) -> str:
    """ "protocol.seed: 0 -> 1; epochs: None -> 5" for two nested settings dicts."""
    a, b = _flatten(_plain(old)), _flatten(_plain(new))
    parts = [
        f"{k}: {a.get(k)!r} -> {b.get(k)!r}"
        for k in sorted(set(a) | set(b))
        if a.get(k) != b.get(k)
    ]
    text = "; ".join(parts) or "unknown difference"
    return text if len(text) <= 400 else text[:397] + "..."


class _State:
    """``OUT_DIR/reproduce.json``: per step its settings (fingerprint), done flag and seconds."""

    def __init__(self, out: Path) -> None:
        self.path = out / STATE_FILE
        self.steps: dict[str, dict[str, Any]] = {}
        if self.path.exists():
            d = read_json(self.path, "reproduce state")
            if not isinstance(d, dict) or d.get("format") != STATE_FORMAT:
                raise EctskinError(
                    f"{self.path}: not an ectskin reproduce state (format {STATE_FORMAT!r})"
                )
            self.steps = dict(d.get("steps") or {})

    def save(self) -> None:
        write_json_atomic(
            self.path,
            {"format": STATE_FORMAT, "version": 1, "ectskin": __version__, "steps": self.steps},
        )

    def settings(self, step: str) -> dict[str, Any] | None:
        return (self.steps.get(step) or {}).get("settings")

    def done(self, step: str, settings: Mapping[str, Any]) -> bool:
        s = self.steps.get(step) or {}
        return bool(s.get("done")) and s.get("settings") == _plain(settings)

    def start(self, step: str, settings: Mapping[str, Any]) -> None:
        self.steps[step] = {"settings": _plain(settings), "done": False}
        self.save()

    def finish(self, step: str, seconds: float, **info: Any) -> None:
        self.steps[step].update(done=True, seconds=float(seconds), **info)
        self.save()


class _Runner:
    """Runs the steps in order, reusing finished ones and refusing conflicting leftovers."""

    def __init__(self, out: Path, force: bool) -> None:
        self.out = out
        self.force = force
        self.state = _State(out)
        self.timings: dict[str, float] = {}
        self.reused: list[str] = []

    def step(self, name: str, settings: Mapping[str, Any], outputs: list[Path], fn) -> Any:
        """Run ``fn()`` for step ``name`` unless it finished with ``settings`` before.

        ``outputs``: the files/folders the step writes. Present but made with other settings (or
        of unknown origin) → error, or removed first with ``force``. ``fn`` returns the step's
        result; a reused step returns None.
        """
        settings = _plain(settings)
        existing = [p for p in outputs if p.exists()]
        if existing and self.state.done(name, settings):
            self.timings[name] = float(self.state.steps[name].get("seconds", 0.0))
            self.reused.append(name)
            log.info(
                "%s: reusing the finished step (%s)",
                name,
                ", ".join(str(p.relative_to(self.out)) for p in existing),
            )
            return None
        old = self.state.settings(name)
        resumable = old == settings  # interrupted with the same settings: resume in place
        if existing and not resumable:
            what = ", ".join(str(p.relative_to(self.out)) for p in existing)
            if not self.force:
                why = (
                    f"they were made with other settings ({_diff(old, settings)})"
                    if old is not None
                    else "their origin is unknown (no record in reproduce.json)"
                )
                raise EctskinError(
                    f"{self.out}: step {name!r} would overwrite {what}: {why}. Use --force "
                    f"(force=True) to redo it, or another output folder"
                )
            log.warning("%s: --force: removing %s", name, what)
            for p in existing:
                shutil.rmtree(p) if p.is_dir() else p.unlink()
        elif existing:
            log.info("%s: resuming an interrupted step", name)
        self.state.start(name, settings)
        t0 = time.perf_counter()
        result = fn()
        dt = time.perf_counter() - t0
        self.timings[name] = dt
        self.state.finish(name, dt)
        log.info("%s: done in %.1f s", name, dt)
        return result


def _load_or_simulate(
    runner: _Runner, protocol: Any, recording: Any, workers: int | None, progress: bool
) -> tuple[Path, dict[str, Any]]:
    """Step "simulate": OUT_DIR/data.h5 from the twin (or from a given recording)."""
    from ectskin.io.hdf5 import write_recording

    path = runner.out / "data.h5"
    if recording is not None:
        import numpy as np

        h = hashlib.blake2b(digest_size=8)
        for t in recording.trials:
            h.update(t.name.encode())
            h.update(np.ascontiguousarray(t.capacitance).tobytes())
        settings = {
            "source": "given recording",
            "digest": h.hexdigest(),
            "n_trials": recording.n_trials,
        }

        def make() -> None:
            write_recording(recording, path, overwrite=True)
    else:
        settings = {"source": "ectskin.twin", "protocol": protocol.to_dict()}
        if path.exists() and runner.state.settings("simulate") is None and not runner.force:
            # a data.h5 put there by hand: reuse it when it holds the same protocol
            from ectskin.io.hdf5 import read_recording

            try:
                meta_protocol = read_recording(path).meta.get("protocol")
            except EctskinError as exc:
                raise EctskinError(
                    f"{path} exists but is not a readable recording of this protocol ({exc}); "
                    f"use --force to simulate again, or another output folder"
                ) from None
            found = _plain(meta_protocol)
            want = _plain(settings["protocol"])
            if found != want:
                detail = _diff(found, want) if isinstance(found, dict) else "no protocol stored"
                raise EctskinError(
                    f"{path} holds a recording of another protocol ({detail}); use --force to "
                    f"simulate again, or another output folder"
                )
            log.info("simulate: %s holds the same protocol; reusing it", path)
            runner.state.start("simulate", settings)
            runner.state.finish("simulate", 0.0, adopted=True)

        def make() -> None:
            from ectskin.twin import simulate_experiment

            rec = simulate_experiment(protocol, workers=workers, progress=progress)
            write_recording(rec, path, overwrite=True)

    runner.step("simulate", settings, [path], make)
    return path, settings


def _run_settings(
    name: str, data_settings: Mapping[str, Any], profile: str, seed: int, epochs: int | None
) -> dict[str, Any]:
    task, window, prior = RUNS[name]
    return {
        "data": _digest(data_settings),
        "task": task,
        "window": window,
        "prior": prior,
        "profile": RUN_PROFILES.get(name, profile),
        "seed": seed,
        "epochs": epochs,
    }


def _epochs_for(name: str, profile: str, epochs: Any) -> int | None:
    """Epochs of run ``name``: ``epochs`` (int for all, or {run: int}; a "touch" entry also applies
    to "touch_robust", a "track" entry to the ablations), else the profile's (ablations under
    ``quick``: :data:`QUICK_ABLATION_EPOCHS`; "touch_robust": the robust profile's)."""
    if isinstance(epochs, Mapping):
        if name in epochs:
            return int(epochs[name])
        if name in ABLATIONS.values() and "track" in epochs:
            return int(epochs["track"])
        if name == "touch_robust" and "touch" in epochs:
            return int(epochs["touch"])
        epochs = None
    if epochs is not None:
        return int(epochs)
    if profile == "quick" and name in ABLATIONS.values():
        return QUICK_ABLATION_EPOCHS
    return None


def reproduce(
    out_dir: str | Path,
    *,
    profile: str = "quick",
    seed: int = 0,
    workers: int | None = None,
    force: bool = False,
    protocol: Any = None,
    recording: Any = None,
    epochs: int | Mapping[str, int] | None = None,
    ablations: bool = True,
    baselines: bool = True,
    characterize: bool = True,
    robust: bool = True,
    device: str | None = None,
    threads: int | str | None = "auto",
    progress: bool = True,
) -> dict[str, Any]:
    """Run the whole reproduction into ``out_dir`` and return the metrics written to metrics.json.

    Parameters
    ----------
    out_dir : path
        Output folder (created). Finished steps found there are reused, see the module docstring.
    profile : "quick" | "paper"
        Training settings (:data:`ectskin.learn.train.PROFILES`).
    seed : int
        Seeds the simulation protocol (when ``protocol`` is None), the splits and the training.
    workers : int, optional
        Simulation processes (default: all cores).
    force : bool
        Redo steps whose earlier results in ``out_dir`` were made with other settings.
    protocol : ectskin.twin.Protocol, optional
        The experiment to simulate (default: the paper's, ``Protocol(seed=seed)``).
    recording : Recording, optional
        Use this recording instead of simulating one (written to ``out_dir/data.h5``).
    epochs : int or {run name: int}, optional
        Override the profile's epochs (run names: "touch", "touch_robust", "track",
        "track_no_prior", "track_window_1"; a "touch" entry also applies to "touch_robust", a
        "track" entry to the ablations).
    ablations, baselines, characterize : bool
        Include the two tracking ablations, the baselines, the twin's characterisation.
    robust : bool
        Also train and evaluate the TouchMLP with the ``robust`` profile (``runs/touch_robust``,
        ``touch.robust`` in metrics.json, ``figures/fig7_confusion_robust.png``).
    device : str, optional
        Training device (default: CUDA when available).
    threads : int, "auto" or None
        CPU threads of torch during training and evaluation (see :func:`resolve_threads`;
        default "auto": 1 on small machines, where more threads gain nothing and oversubscribe
        cores shared with other jobs; None: torch's default).
    """
    check_option("profile", profile, PROFILES)
    if workers is not None and workers < 1:
        raise EctskinError(f"workers must be >= 1, got {workers}")
    with _torch_threads(resolve_threads(threads)):
        return _reproduce(
            out_dir, profile, seed, workers, force, protocol, recording, epochs, ablations,
            baselines, characterize, robust, device, progress,
        )


@contextmanager
def _torch_threads(n_threads: int | None):
    """Run the block with ``n_threads`` torch CPU threads (None: leave torch's setting)."""
    if n_threads is None:
        yield
        return
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n_threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


#: ``threads="auto"`` uses one torch thread on machines with at most this many cores.
AUTO_ONE_THREAD_CORES = 4


def resolve_threads(threads: int | str | None) -> int | None:
    """Torch CPU threads for ``threads``: an int ≥ 1 as given; None = torch's default (one per
    core); "auto" = 1 on machines with ≤ :data:`AUTO_ONE_THREAD_CORES` cores, else torch's
    default. The models are small: on 2 cores a C2DT batch of 256 trains as fast on 1 thread as
    on 2 (0.127 vs 0.139 s measured), and several times slower on 2 when other jobs share the
    cores (0.127 vs 0.606 s)."""
    if threads == "auto":
        import os

        return 1 if (os.cpu_count() or 1) <= AUTO_ONE_THREAD_CORES else None
    if threads is None:
        return None
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise EctskinError(f"threads must be an integer >= 1, 'auto' or None, got {threads!r}")
    return threads


def _reproduce(
    out_dir,
    profile,
    seed,
    workers,
    force,
    protocol,
    recording,
    epochs,
    ablations,
    baselines,
    characterize,
    robust,
    device,
    progress,
) -> dict[str, Any]:
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise EctskinError(f"output folder {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    if recording is None and protocol is None:
        from ectskin.twin import Protocol

        protocol = Protocol(seed=seed)
    runner = _Runner(out, force)

    # 1. data
    data_path, data_settings = _load_or_simulate(runner, protocol, recording, workers, progress)

    # 2. characterisation of the twin (paper §2.2, Fig. 3 / 4)
    if characterize and recording is None:
        from ectskin.twin.characterize import characterize as run_characterize

        char_dir = out / "characterize"
        runner.step(
            "characterize",
            {"seed": seed},
            [char_dir],
            lambda: run_characterize(char_dir, seed=seed),
        )

    # 3. training
    from ectskin.learn.train import main_from_args

    names = (
        ["touch"]
        + (["touch_robust"] if robust else [])
        + ["track"]
        + (list(ABLATIONS.values()) if ablations else [])
    )
    train_info: dict[str, Any] = {}
    for name in names:
        task, window, prior = RUNS[name]
        n_epochs = _epochs_for(name, profile, epochs)
        settings = _run_settings(name, data_settings, profile, seed, n_epochs)
        run_dir = out / "runs" / name
        run_profile = settings["profile"]

        def fit(
            task=task,
            window=window,
            prior=prior,
            n_epochs=n_epochs,
            run_dir=run_dir,
            run_profile=run_profile,
        ):
            return main_from_args(
                task,
                data_path,
                run_dir,
                profile=run_profile,
                seed=seed,
                epochs=n_epochs,
                window=window,
                prior=prior,
                resume=True,
                device=device,
                progress=progress,
            )

        log.info(
            "train %s: %s, window %d, prior %s, profile %s", name, task, window, prior, run_profile
        )
        summary = runner.step(f"train_{name}", settings, [run_dir], fit)
        if summary is not None:
            train_info[name] = summary

    # 4. evaluation (+ baselines on the same split for the two main runs)
    from ectskin.learn.evaluate import evaluate_run

    results: dict[str, dict[str, Any]] = {}
    for name in names:
        run_dir = out / "runs" / name
        main_run = name in ("touch", "track")
        settings = {
            **_run_settings(name, data_settings, profile, seed, _epochs_for(name, profile, epochs)),
            "baselines": baselines and main_run,
        }
        runner.step(
            f"evaluate_{name}",
            settings,
            [run_dir / "metrics.json"],
            lambda run_dir=run_dir, main_run=main_run: evaluate_run(
                run_dir, data_path, baselines=baselines and main_run, figures=True, seed=seed
            ),
        )
        results[name] = read_json(run_dir / "metrics.json", "run metrics")

    # 5. metrics.json + report
    metrics = _combine(results, runner, profile, seed, protocol, data_settings, data_path)
    figures = _copy_figures(out, names)
    metrics["figures"] = {caption: rel for caption, rel in figures.items()}
    metrics["timings_s"]["total"] = time.perf_counter() - t_start
    write_json_atomic(out / "metrics.json", metrics)
    metrics = read_json(out / "metrics.json", "metrics")  # return exactly what was saved
    from ectskin.report.report import write_report

    write_report(out, metrics, figures)
    if runner.reused:
        log.info("reused finished steps: %s", ", ".join(runner.reused))
    log.info(
        "reproduction written to %s (report.md, report.html, metrics.json) in %.1f s",
        out,
        metrics["timings_s"]["total"],
    )
    return metrics


def _combine(
    results: Mapping[str, dict],
    runner: _Runner,
    profile: str,
    seed: int,
    protocol: Any,
    data_settings: Mapping[str, Any],
    data_path: Path,
) -> dict[str, Any]:
    """The OUT_DIR/metrics.json dict from the per-run metrics (see ``ectskin.report.report``)."""
    from ectskin.report.report import machine_info

    m: dict[str, Any] = {
        "format": "ectskin.metrics",
        "version": 1,
        "profile": profile,
        "seed": seed,
        "created_utc": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
    }
    if "touch" in results:
        m["touch"] = dict(results["touch"].get("touch", {}))
        if "touch_robust" in results:
            r = results["touch_robust"].get("touch", {})
            m["touch"]["robust"] = {k: r[k] for k in ROBUST_KEYS if k in r}
    if "track" in results:
        m["track"] = dict(results["track"].get("track", {}))
        abl = {}
        for key, name in ABLATIONS.items():
            if name in results:
                r = results[name].get("track", {})
                abl[key] = {
                    k: r.get(k)
                    for k in (
                        "ad_mm_mean",
                        "ad_mm_std",
                        "ad_mm_median",
                        "n_test_samples",
                        "window",
                        "prior",
                        "per_marker",
                        "worst_trajectory",
                        "training",
                        "examples",
                    )
                    if k in r
                }
        if abl:
            m["track"]["ablations"] = abl
    n_trials = None
    try:
        from ectskin.io.hdf5 import list_trials

        n_trials = len(list_trials(data_path))
    except EctskinError:
        pass
    m["data"] = {"file": data_path.name, "source": data_settings.get("source"), "trials": n_trials}
    if protocol is not None:
        m["protocol"] = protocol.to_dict()
    m["timings_s"] = dict(runner.timings)
    m["reused"] = list(runner.reused)
    m["machine"] = machine_info()
    return m


def _copy_figures(out: Path, runs: list[str]) -> dict[str, str]:
    """Copy the report's figures of ``runs`` into OUT_DIR/figures; {caption: path relative to
    OUT_DIR}."""
    fig_dir = out / "figures"
    fig_dir.mkdir(exist_ok=True)
    figures: dict[str, str] = {}
    for run, name, caption, copy_name in REPORT_FIGURES:
        src = out / "runs" / run / name
        if run in runs and src.is_file():
            dst = fig_dir / copy_name
            shutil.copyfile(src, dst)
            figures[caption] = dst.relative_to(out).as_posix()
    return figures
