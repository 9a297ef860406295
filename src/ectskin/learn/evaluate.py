"""Evaluation of a trained run on its test split: :func:`evaluate_run`.

The stages, each a short function:

1. :func:`read_run`: the run folder's files, each read and checked once (``model.pt``,
   ``split.json``, ``config.json``, ``metrics.csv``; see :mod:`ectskin.learn.runfiles`);
2. the recording (given, or the file named in ``split.json``), its test trials
   (:func:`choose_test_trials`) and its calibration (:func:`calibration`), and the run's task's data
   set;
3. the task's batched prediction and test metrics (:mod:`ectskin.learn.tasks`,
   :mod:`ectskin.learn.metrics`), its baselines on the same split, its figures and the learning
   curves;
4. ``metrics.json``, written atomically.

A touch run trained with a model choice (``--model auto`` or a classical model,
:mod:`ectskin.learn.candidates`) is evaluated with the model its ``candidates.json`` selects
(``selected_model``); ``candidates`` adds each candidate's test accuracy beside its validation
accuracy: the MLP (``model.pt``), the selected classical model (``model.skops``), the others refit
on the train split with their recorded settings and seed (as training fit them).

Which trials are test data (``test_trials``, ``--test-trials``; :func:`choose_test_trials`): by
default ("auto") every trial of the recording except those the run was trained or validated on,
recognised by their readouts (the trial digests ``split.json`` stores; a run that stores none:
by trial name). On the training recording (or a copy of it) that is the run's test split; a
recording of another day or of other inflation states is test data whole. "split" takes the
run's test split by trial name (a re-simulation of the same trials, e.g. with the hand off);
"all" every trial (refused when some are training trials). The metrics say which reading was
taken (``test_data``).

The calibration (Eq. 2) of a model that reads frames against a rest state
(:func:`calibration`): ``reference`` (``--reference REC.h5``: the rest state of that
recording) if given; else the evaluated recording's own (rest-state trials or per-trial
references); else the training recording's rest reference stored in the run. A touch run
trained with reference "state" or "inflation" (:mod:`ectskin.io.inflation_reference`) is
calibrated as it was trained: against each state's no-contact trials of the evaluated
recording, or by the inflation model stored in the run. The metrics say which (``reference``).

Where the results go (:func:`evaluation_files`): on the run's own data (the file named in
``split.json``) ``metrics.json`` and the figures in the run folder; on other data
``metrics_<data file stem>.json`` and figures ``<figure>_<data file stem>.<format>`` beside
them, so an evaluation on another recording never replaces the run's own. ``out`` writes into
another folder instead (names without the suffix). An earlier evaluation is never replaced
unless ``overwrite`` (``--overwrite``): the call stops before any work, naming the file; so does
an output that is one of the inputs (``out`` being the recording, say), and a run directory that
is a file.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from torch import nn

from ectskin._check import EctskinError, check_option, check_seed
from ectskin._files import save_figure_atomic, write_json_atomic
from ectskin.io import Recording, read_recording
from ectskin.io.calibration import ReferenceChoice, choose_reference
from ectskin.learn import contact_choice as cc
from ectskin.learn.candidates import (
    CLASSICAL_FILE,
    accuracy,
    fit_classical,
    load_classical,
    read_candidates,
    thread_limit,
)
from ectskin.learn.channels import measured_channels
from ectskin.learn.checkpoint import check_channels, check_layout, load_checkpoint
from ectskin.learn.data import SampleData
from ectskin.learn.data.touch import stored_touch_reference
from ectskin.learn.extra_train import with_extra
from ectskin.learn.runfiles import (
    check_outputs,
    check_run_dir,
    evaluation_inputs,
    read_metrics,
    read_run_config,
    read_split,
    stored_rest_reference,
    training_summary,
)
from ectskin.learn.splits import (
    TEST_TRIALS,
    EvaluatedTrials,
    choose_test_trials,
    stored_trial_digests,
    trial_digests,
)
from ectskin.learn.tasks import EvalCase, Task, get_task, task_for_model
from ectskin.viz import DEFAULT_DPI, check_figure_options, figure_file
from ectskin.viz.learning import plot_learning_curves

log = logging.getLogger(__name__)

__all__ = [
    "CURVES_FIGURE",
    "TEST_TRIALS",
    "EvaluatedTrials",
    "EvaluationFiles",
    "Run",
    "calibration",
    "choose_test_trials",
    "evaluate_run",
    "evaluation_files",
    "read_run",
]

#: The learning-curves figure's stem (not written for other data: the curves are the run's).
CURVES_FIGURE = "learning_curves"
#: checkpoint ``extra`` fields copied into the metrics' ``training``
EXTRA_TRAINING_FIELDS = ("device", "profile", "seed", "world_size")


@dataclass
class Run:
    """A run directory's files, read and checked (see :func:`read_run`)."""

    path: Path
    task: Task
    model: nn.Module | None  # the network of model.pt (None: a classical model alone)
    config: Any  # the answering model's config (a ClassicalConfig for a classical model)
    payload: dict[str, Any]  # the checkpoint (extra: pair names, kept epoch, profile, ...)
    split: dict[str, Any]  # split.json
    run_config: dict[str, Any] | None  # config.json (None: the run has none)
    metrics_rows: list[dict[str, float]]  # metrics.csv ([] when absent)
    candidates: dict[str, Any] | None = None  # candidates.json (None: an MLP run)
    classical: Any = None  # the selected classical model (model.skops; ClassicalModel for touch)

    @property
    def selected(self) -> str:
        """The model the run answers with: the network ("mlp"; "contactnet" for contact) or a
        classical candidate's name."""
        if self.candidates is None:
            return cc.NET if self.task.name == "contact" else "mlp"
        return str(self.candidates["selected"])

    @property
    def model_file(self) -> Path:
        return self.path / (CLASSICAL_FILE if self.classical is not None else "model.pt")


def read_run(run_dir: str | Path) -> Run:
    """Read a run directory of ``ectskin train``: the model, its task and the run's files.

    Raises EctskinError naming the file for a missing folder or model, a malformed
    ``split.json``, ``config.json`` or ``metrics.csv``, or files of another task."""
    run = Path(run_dir)
    check_run_dir(run)
    candidates = read_candidates(run)
    contact = candidates is not None and candidates.get("task") == "contact"
    net = cc.NET if contact else "mlp"
    model, config, payload, classical = None, None, {}, None
    if candidates is None or net in candidates["candidates"]:
        model, config, payload = load_checkpoint(run / "model.pt")
        task = task_for_model(payload["kind"])
    else:
        task = get_task("contact" if contact else "touch")  # a classical model alone
    if contact and candidates["selected"] != net:
        classical = cc.load_selected(run, candidates)
        config = classical.config
    elif not contact and candidates is not None and candidates["selected"] != "mlp":
        classical = load_classical(run / CLASSICAL_FILE)
        if classical.name != candidates["selected"]:
            raise EctskinError(
                f"{run / CLASSICAL_FILE}: holds {classical.name!r} but candidates.json selects "
                f"{candidates['selected']!r}; train again"
            )
        config = classical.config
    split = read_split(run)
    if split.get("task", task.name) != task.name:
        raise EctskinError(
            f"{run / 'split.json'}: task {split.get('task')!r} does not match the model "
            f"in model.pt ({payload.get('kind')!r})"
        )
    metrics_path = run / "metrics.csv"
    return Run(
        path=run,
        task=task,
        model=model,
        config=config,
        payload=payload,
        split=split,
        run_config=read_run_config(run, task.name),
        metrics_rows=read_metrics(metrics_path) if metrics_path.is_file() else [],
        candidates=candidates,
        classical=classical,
    )


@dataclass(frozen=True)
class EvaluationFiles:
    """Where one evaluation writes: ``metrics`` (the JSON file) and ``figures`` {figure stem:
    file}, in ``folder``; ``own_data`` when it evaluates the run's own recording."""

    folder: Path
    metrics: Path
    figures: dict[str, Path]
    own_data: bool

    def outputs(self, metrics: bool = True) -> list[Path]:
        """The files written: the figures, and the metrics JSON with ``metrics``."""
        return ([self.metrics] if metrics else []) + list(self.figures.values())


def evaluation_files(
    run: Run,
    data: Any = None,
    *,
    out: str | Path | None = None,
    figures: bool = True,
    figure_format: str = "png",
) -> EvaluationFiles:
    """The files an evaluation of ``run`` on ``data`` writes (see the module docstring): in the
    run folder, with the suffix ``_<data file stem>`` when ``data`` is not the file named in
    ``split.json``; in ``out`` (no suffix) when given."""
    own = _is_own_data(data, run)
    suffix = "" if own or out is not None else f"_{_data_stem(data)}"
    folder = run.path if out is None else Path(out)
    # the learning curves belong to the run: drawn unless this is a side evaluation in its folder
    curves = [CURVES_FIGURE] if not suffix and run.metrics_rows else []
    stems = list(run.task.figure_captions) + curves
    figs = (
        {stem: folder / figure_file(f"{stem}{suffix}", figure_format) for stem in stems}
        if figures
        else {}
    )
    return EvaluationFiles(folder, folder / f"metrics{suffix}.json", figs, own)


def _is_own_data(data: Any, run: Run) -> bool:
    """Whether ``data`` (None, a path or a Recording) is the recording named in split.json."""
    if data is None:
        return True
    stored = run.split.get("data")
    source = data.source if isinstance(data, Recording) else data
    if not stored or source is None:
        return False
    stored_path = Path(stored)
    if not stored_path.is_absolute():
        stored_path = run.path / stored_path
    return Path(source).resolve() == stored_path.resolve()


def _data_stem(data: Any) -> str:
    """The name other data is known by in file names: its file's stem ("recording" for a
    Recording without a source file)."""
    source = data.source if isinstance(data, Recording) else data
    return Path(source).stem if source else "recording"


def evaluate_run(
    run_dir: str | Path,
    data: Any = None,
    *,
    baselines: bool = True,
    figures: bool = True,
    write: bool = True,
    seed: int = 0,
    out: str | Path | None = None,
    overwrite: bool = False,
    figure_format: str = "png",
    dpi: int = DEFAULT_DPI,
    test_trials: str = "auto",
    reference: Any = None,
) -> dict[str, Any]:
    """Evaluate a trained run on test data; write the metrics JSON and the figures.

    Parameters
    ----------
    run_dir : path
        A run directory of ``ectskin train`` (``model.pt``, ``split.json``, ``metrics.csv``).
    data : Recording or path, optional
        The recording; default the data file named in ``split.json``. The data set is rebuilt
        with the run's settings (task, window, prior) and calibrated as :func:`calibration`
        says.
    baselines : bool
        Also fit the task's baselines (:mod:`ectskin.learn.baselines`) on the run's training
        trials and score them on the same test frames (touch: majority, logistic regression,
        random forest, k-NN; tracking: markers do not move, mean pose, ridge regression) on the
        run's training trials (from ``data``, else the training recording that ``split.json``
        names, with its extra training trials; else skipped, ``baselines_skipped`` says why).
    figures : bool
        Write the task's figures (Fig. 7 for touch, Fig. 9 and Fig. 10 for tracking) and, on the
        run's own data, the learning curves.
    write : bool
        Write the metrics JSON (atomically).
    seed : int
        Seed of the baselines' subsampling.
    out : path, optional
        The folder to write into (default: the run folder). Where the files go and what they
        are called: :func:`evaluation_files` (on data other than the run's own, the run folder
        gets ``metrics_<data file stem>.json`` and suffixed figures).
    overwrite : bool
        Replace the files of an earlier evaluation; without it an existing one stops the call
        before any work, naming the file.
    figure_format, dpi : str, int
        The figures' file format (``png``, ``pdf``, ``svg``) and resolution
        (:func:`ectskin.viz.check_figure_options`).
    test_trials : "auto" | "split" | "all"
        Which trials of the recording are test data (:func:`choose_test_trials`).
    reference : Recording or path, optional
        A recording whose rest state calibrates the data (:func:`calibration`).

    Returns
    -------
    dict
        ``{"data": ..., "touch": {...}}`` for a TouchMLP run or ``{"data": ..., "track": {...}}``
        for a C2DT run (see :func:`ectskin.learn.metrics.touch_metrics` /
        :func:`~ectskin.learn.metrics.track_metrics`), each with ``baselines``, ``training``
        (epochs, best epoch, seconds from ``metrics.csv``), ``split`` (trial counts: the run's
        train and val, the test trials evaluated), ``test_data`` (which trials were taken and
        why), ``reference`` (the calibration used), the ``figures`` written ({file name:
        caption}) and ``evaluate_seconds``; tracking adds ``window``, ``prior`` and ``examples``
        (the 6 samples of Fig. 9 with their AD, the worst of them, and the trajectory of
        Fig. 10).
    """
    t0 = time.perf_counter()
    figure_format, dpi = check_figure_options(figure_format, dpi)
    check_option("test_trials", test_trials, TEST_TRIALS)
    seed = check_seed("seed", seed)
    inputs = evaluation_inputs(run_dir, data, reference, out)
    run = read_run(run_dir)
    files = evaluation_files(run, data, out=out, figures=figures, figure_format=figure_format)
    check_outputs(files.outputs(write), inputs)
    existing = [p for p in files.outputs(write) if p.exists()]
    if existing and not overwrite:
        more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
        raise EctskinError(
            f"{existing[0]}{more}: written by an earlier evaluation; pass --overwrite to "
            "replace it, or -o/--out DIR to write elsewhere"
        )
    rec, data_desc = _recording(data, run)
    check_layout(run.model_file, run.config, rec.layout)
    calib = calibration(run, rec, reference, data_desc)
    log.info("calibration: %s", calib.text)
    case, chosen, train = _test_case(run, rec, calib, test_trials, data_desc)
    m = run.task.test_metrics(case)
    if run.task.name in ("touch", "contact"):
        m["selected_model"] = run.selected
    if run.candidates is not None:
        on_test = cc.candidates_on_test if run.task.name == "contact" else _candidates_on_test
        m["candidates"] = on_test(run, case, train)
    if baselines:
        if train.data is not None:
            m["baselines"] = run.task.baseline_metrics(train.data, case.test, seed=seed)
            if notes := run.task.baselines_left_out(train.data):
                m["baselines_left_out"] = notes
        else:
            m["baselines"], m["baselines_skipped"] = {}, train.note
            log.warning("baselines skipped: %s", train.note)
    m["training"] = _training(run)
    history = m["training"].pop("history", None)
    figs: dict[str, str] = {}
    if figures:
        drawn = run.task.figures(case, m)
        captions = dict(run.task.figure_captions)
        if CURVES_FIGURE in files.figures and history:
            drawn[CURVES_FIGURE] = plot_learning_curves(
                history, title=f"{run.task.name}: {run.path.name}"
            )
            captions[CURVES_FIGURE] = "training and validation loss per epoch"
        for stem, fig in drawn.items():
            save_figure_atomic(fig, files.figures[stem], dpi=dpi)
            figs[files.figures[stem].name] = captions[stem]
    m["split"] = {
        "train": len(run.split["train"]),
        "val": len(run.split["val"]),
        "test": len(chosen.names),
    }
    m["test_data"] = chosen.to_json()
    m["reference"] = calib.to_json()
    m["figures"] = figs
    m["evaluate_seconds"] = time.perf_counter() - t0
    result = {"data": data_desc, run.task.name: m}
    if write:
        write_json_atomic(files.metrics, result)
    written = ([files.metrics] if write else []) + [files.folder / name for name in figs]
    if written:
        log.info("wrote %s", ", ".join(str(p) for p in written))
    return result


def _recording(data: Any, run: Run) -> tuple[Recording, str]:
    """The recording to evaluate on: ``data`` (Recording or path) or the one named in
    split.json; with a description of where it came from."""
    if isinstance(data, Recording):
        return data, "given Recording"
    if data is None:
        path = _training_file(run)
        if path is None:
            raise EctskinError(
                f"{run.path / 'split.json'}: names no data file; pass the recording "
                "(--data DATA.h5)"
            )
        if not path.exists():
            raise EctskinError(
                f"{run.path / 'split.json'}: data file {path} no longer exists; pass --data DATA.h5"
            )
    else:
        path = Path(data)
    return read_recording(path), str(path)


def _training_file(run: Run) -> Path | None:
    """The training recording named in split.json (relative: to the run folder), or None."""
    stored = run.split.get("data")
    if not stored:
        return None
    path = Path(stored)
    return path if path.is_absolute() else run.path / path


# ============================================================================ calibration
def calibration(
    run: Run, rec: Recording, reference: Any = None, source: str = "data"
) -> ReferenceChoice:
    """The calibration reference for evaluating ``run`` on ``rec``
    (:func:`ectskin.io.calibration.choose_reference`): ``reference`` (a Recording or its path:
    its rest state) if given; else ``rec``'s own; else the training recording's rest reference
    stored in the run (``split.json``). A model that calibrates against each trajectory's first
    frame takes none (a ``reference`` is an error)."""
    if not run.task.uses_rest_reference(run.config):
        if reference is not None:
            raise EctskinError(
                f"--reference does not apply to {run.path}: its model calibrates each trajectory "
                "against its first frame (prior knowledge)"
            )
        return ReferenceChoice("auto", "trajectory", "each trajectory's first frame (prior)")
    follows = _follows_inflation(run)
    if follows is not None:
        if reference is not None:
            raise EctskinError(
                f"--reference does not apply to {run.path}: it calibrates against {follows.text}"
            )
        return follows
    given, name = None, None
    if reference is not None:
        given = reference if isinstance(reference, Recording) else read_recording(reference)
        name = "given Recording" if isinstance(reference, Recording) else str(reference)
    split_file = str(run.path / "split.json")
    stored = stored_rest_reference(run.split, rec.layout.pair_names, split_file)
    try:
        return choose_reference(
            rec,
            given=given,
            given_name=name,
            stored=stored,
            stored_from=str(run.split.get("data") or "the training recording"),
            channels=measured_channels(rec),
            source=source,
        )
    except EctskinError as exc:
        if stored is not None or given is not None:
            raise
        raise EctskinError(
            f"{exc}; the run {run.path} stores no rest reference (trained before runs stored "
            "one): pass --reference REC.h5, a recording of the same skin with one (e.g. the "
            "training recording)"
        ) from None


# ============================================================================ data sets
@dataclass(frozen=True)
class _Train:
    """The run's training trials as a data set (for the baselines and the candidates' refits),
    or None with a ``note`` saying why not."""

    data: SampleData | None
    note: str = ""


def _test_case(
    run: Run, rec: Recording, calib: ReferenceChoice, mode: str, source: str
) -> tuple[EvalCase, EvaluatedTrials, _Train]:
    """The run's data set of ``rec``, its test trials (:func:`choose_test_trials` among the
    data set's trials) and the model's predictions on them; the run's training trials (from
    ``rec`` when it holds them all, else the training recording)."""
    task = run.task
    ds = task.dataset(rec, reference=calib.value, **task.dataset_options(run.config))
    check_channels(run.model_file, run.config, ds.n_pairs)
    chosen = choose_test_trials(
        run.split,
        rec,
        mode,
        source=source,
        split_file=str(run.path / "split.json"),
        trials=ds.group_names,
    )
    log.info("test data: %s", chosen.text)
    wanted = set(chosen.names)
    test_ids = np.array([i for i, n in enumerate(ds.group_names) if n in wanted], dtype=np.int64)
    test = ds.select(test_ids)
    if run.classical is not None:
        pred = run.classical.predict(test.x)
    else:
        pred = task.predict(run.model, test)
    case = EvalCase(data=ds, test=test, pred=pred, recording=rec, config=run.config)
    train = _training_trials(run, rec, ds, chosen)  # with the run's extra training trials:
    data, note = with_extra(train.data, train.note, run.split, task, reference=calib.value,
                            options=task.dataset_options(run.config), run_dir=run.path)
    return case, chosen, _Train(data, note)


def _training_trials(run: Run, rec: Recording, ds: SampleData, chosen: EvaluatedTrials) -> _Train:
    """The run's training split as a data set: from the evaluated data when it holds every
    training trial (recognised as :func:`choose_test_trials` does), else from the training
    recording named in split.json when it is there unchanged; else None with the reason."""
    names = run.split["train"]
    by_name = chosen.by == "names" and set(names) <= set(chosen.left_out)
    if chosen.reading == "run_split" or by_name:
        return _select_names(ds, names)
    stored = stored_trial_digests(run.split, str(run.path / "split.json"))
    if chosen.by == "digests" and stored is not None:
        wanted = {stored[n] for n in names if n in stored}
        mine = trial_digests(rec)
        present = [t.name for t in rec.trials if mine[t.name] in wanted]
        if len(present) == len(names):
            return _select_names(ds, present)
    path = _training_file(run)
    if path is None or not path.is_file():
        return _Train(None, f"the run's training recording {path} is not there to fit them on")
    train_rec = read_recording(path)
    if stored is not None:
        theirs = trial_digests(train_rec)
        changed = [n for n in names if theirs.get(n) != stored.get(n)]
        if changed:
            return _Train(
                None,
                f"the training recording {path} changed since training (trial(s) {changed[:3]})",
            )
    task, follows = run.task, _follows_inflation(run)
    train_ds = task.dataset(
        train_rec,
        reference="auto" if follows is None else follows.value,
        **task.dataset_options(run.config),
    )
    return _select_names(train_ds, names)


def _follows_inflation(run: Run) -> ReferenceChoice | None:
    """A touch run's stored reference that follows the inflation, else None (rest state)."""
    extra, source = run.payload.get("extra", {}), str(run.path / "split.json")
    return stored_touch_reference(run.split, extra, source) if run.task.name == "touch" else None


def _select_names(ds: SampleData, names: list[str]) -> _Train:
    index = {n: i for i, n in enumerate(ds.group_names)}
    ids = np.array(sorted(index[n] for n in names if n in index), dtype=np.int64)
    if ids.size == 0:
        return _Train(None, "no training trial has samples")
    return _Train(ds.select(ids))


def _candidates_on_test(run: Run, case: EvalCase, train: _Train) -> dict[str, Any]:
    """Every candidate of candidates.json on the test trials: {name: val_accuracy,
    test_accuracy, n_test_frames, n_misclassified, model (where it came from), selected}; a
    candidate refit without training trials at hand has test_accuracy None."""
    test, doc = case.test, run.candidates or {}
    out: dict[str, Any] = {}
    for name, info in doc.get("candidates", {}).items():
        if name == run.selected:
            pred, source = case.pred, run.model_file.name
        elif name == "mlp":
            pred, source = run.task.predict(run.model, test), "model.pt"
        elif train.data is None:
            pred, source = None, f"not refit: {train.note}"
        else:
            settings = info.get("settings") or {}
            with thread_limit(1):
                model, _, _ = fit_classical(
                    name,
                    train.data,
                    seed=int(settings.get("seed", 0)),
                    max_train=settings.get("max_train"),
                )
            pred, source = model.predict(test.x), "refit on the train split"
        out[name] = {
            "val_accuracy": info.get("val_accuracy"),
            "test_accuracy": None if pred is None else accuracy(pred, test.y),
            "n_test_frames": int(test.n_samples),
            "n_misclassified": None if pred is None else int((pred != test.y).sum()),
            "model": source,
            "selected": name == run.selected,
        }
    return out


def _training(run: Run) -> dict[str, Any]:
    """The metrics' ``training``: :func:`training_summary` of the run's files plus the device,
    profile, seed and world size stored in the checkpoint."""
    extra = run.payload.get("extra", {})
    return {
        **training_summary(run.metrics_rows, run.run_config, extra),
        **{k: v for k, v in extra.items() if k in EXTRA_TRAINING_FIELDS},
    }
