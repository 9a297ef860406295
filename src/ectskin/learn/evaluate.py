"""Evaluation of a trained run on its test split: :func:`evaluate_run`.

The stages, each a short function:

1. :func:`read_run`: the run folder's files, each read and checked once (``model.pt``,
   ``split.json``, ``config.json``, ``metrics.csv``; see :mod:`ectskin.learn.runfiles`);
2. the recording (given, or the file named in ``split.json``) and the run's task's data set,
   with the test split re-created from the trial names in ``split.json``;
3. the task's batched prediction and test metrics (:mod:`ectskin.learn.tasks`,
   :mod:`ectskin.learn.metrics`), its baselines on the same split, its figures and the learning
   curves;
4. ``metrics.json``, written atomically.

A touch run trained with a model choice (``--model auto`` or a classical model, see
:mod:`ectskin.learn.candidates`) is evaluated with the model its ``candidates.json`` selects (the
main metrics, with ``selected_model``); ``candidates`` adds every candidate's test accuracy beside
its validation accuracy: the MLP from ``model.pt``, the selected classical model from
``model.skops``, the other classical candidates refit on the train split of the evaluated data
with their recorded settings and seed (the same models training fit on the same data).

Where the results go (:func:`evaluation_files`): on the run's own data (the file named in
``split.json``) ``metrics.json`` and the figures in the run folder; on other data
``metrics_<data file stem>.json`` and figures ``<figure>_<data file stem>.<format>`` beside
them, so an evaluation on another recording never replaces the run's own. ``out`` writes into
another folder instead (names without the suffix). An earlier evaluation is never replaced
unless ``overwrite`` (``--overwrite``): the call stops before any work, naming the file.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from torch import nn

from ectskin._check import EctskinError
from ectskin._files import save_figure_atomic, write_json_atomic
from ectskin.io import Recording, read_recording
from ectskin.learn.candidates import (
    CLASSICAL_FILE,
    ClassicalModel,
    accuracy,
    fit_classical,
    load_classical,
    read_candidates,
    thread_limit,
)
from ectskin.learn.checkpoint import check_channels, check_layout, load_checkpoint
from ectskin.learn.runfiles import (
    read_metrics,
    read_run_config,
    read_split,
    training_summary,
)
from ectskin.learn.splits import split_from_names
from ectskin.learn.tasks import EvalCase, Task, get_task, task_for_model
from ectskin.viz import DEFAULT_DPI, check_figure_options, figure_file
from ectskin.viz.learning import plot_learning_curves

log = logging.getLogger(__name__)

__all__ = [
    "CURVES_FIGURE",
    "EvaluationFiles",
    "Run",
    "evaluate_run",
    "evaluation_files",
    "read_run",
]

#: The stem of the learning-curves figure ``evaluate_run`` writes beside the task's figures
#: (not with an evaluation on other data in the run folder: the curves belong to the run).
CURVES_FIGURE = "learning_curves"
#: checkpoint ``extra`` fields copied into the metrics' ``training``
EXTRA_TRAINING_FIELDS = ("device", "profile", "seed", "world_size")


@dataclass
class Run:
    """A run directory's files, read and checked (see :func:`read_run`)."""

    path: Path
    task: Task
    model: nn.Module | None  # the MLP / C2DT of model.pt (None: a classical model alone)
    config: Any  # the answering model's config (a ClassicalConfig for a classical model)
    payload: dict[str, Any]  # the checkpoint (extra: pair names, kept epoch, profile, ...)
    split: dict[str, Any]  # split.json
    run_config: dict[str, Any] | None  # config.json (None: the run has none)
    metrics_rows: list[dict[str, float]]  # metrics.csv ([] when absent)
    candidates: dict[str, Any] | None = None  # candidates.json (None: an MLP run)
    classical: ClassicalModel | None = None  # the selected classical model (model.skops)

    @property
    def selected(self) -> str:
        """The model the run answers with: "mlp" or a classical candidate's name."""
        return "mlp" if self.candidates is None else str(self.candidates["selected"])

    @property
    def model_file(self) -> Path:
        return self.path / (CLASSICAL_FILE if self.classical is not None else "model.pt")


def read_run(run_dir: str | Path) -> Run:
    """Read a run directory of ``ectskin train``: the model, its task and the run's files.

    Raises EctskinError naming the file for a missing folder or model, a malformed
    ``split.json``, ``config.json`` or ``metrics.csv``, or files of another task.
    """
    run = Path(run_dir)
    if not run.is_dir():
        raise EctskinError(f"run directory {run} does not exist")
    candidates = read_candidates(run)
    model, config, payload, classical = None, None, {}, None
    if candidates is None or "mlp" in candidates["candidates"]:
        model, config, payload = load_checkpoint(run / "model.pt")
        task = task_for_model(payload["kind"])
    else:
        task = get_task("touch")  # only touch runs choose among candidates
    if candidates is not None and candidates["selected"] != "mlp":
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
) -> dict[str, Any]:
    """Evaluate a trained run on its test split; write the metrics JSON and the figures.

    Parameters
    ----------
    run_dir : path
        A run directory of ``ectskin train`` (``model.pt``, ``split.json``, ``metrics.csv``).
    data : Recording or path, optional
        The recording; default the data file named in ``split.json``. The data set is rebuilt
        with the run's settings (task, window, prior, reference) and the split re-created from
        the trial names in ``split.json``.
    baselines : bool
        Also fit and score the task's baselines (:mod:`ectskin.learn.baselines`) on the same
        split (touch: majority, logistic regression, random forest, k-NN; tracking: markers do
        not move, mean pose, ridge regression).
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

    Returns
    -------
    dict
        ``{"data": ..., "touch": {...}}`` for a TouchMLP run or ``{"data": ..., "track": {...}}``
        for a C2DT run (see :func:`ectskin.learn.metrics.touch_metrics` /
        :func:`~ectskin.learn.metrics.track_metrics`), each with ``baselines``, ``training``
        (epochs, best epoch, seconds from ``metrics.csv``), ``split`` (trial counts), the
        ``figures`` written ({file name: caption}) and ``evaluate_seconds``; tracking adds
        ``window``, ``prior`` and ``examples`` (the 6 samples of Fig. 9 with their AD, the
        worst of them, and the trajectory of Fig. 10).
    """
    t0 = time.perf_counter()
    figure_format, dpi = check_figure_options(figure_format, dpi)
    run = read_run(run_dir)
    files = evaluation_files(run, data, out=out, figures=figures, figure_format=figure_format)
    existing = [p for p in files.outputs(write) if p.exists()]
    if existing and not overwrite:
        more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
        raise EctskinError(
            f"{existing[0]}{more}: written by an earlier evaluation; pass --overwrite to "
            "replace it, or -o/--out DIR to write elsewhere"
        )
    rec, data_desc = _recording(data, run)
    check_layout(run.model_file, run.config, rec.layout)
    case, split = _test_case(run, rec)
    m = run.task.test_metrics(case)
    if run.task.name == "touch":
        m["selected_model"] = run.selected
    if run.candidates is not None:
        m["candidates"] = _candidates_on_test(run, case, split)
    if baselines:
        train = case.data.select(split["train"])
        m["baselines"] = run.task.baseline_metrics(train, case.test, seed=seed)
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
    m["split"] = {k: len(run.split[k]) for k in ("train", "val", "test")}
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
        stored = run.split.get("data")
        if not stored:
            raise EctskinError(
                f"{run.path / 'split.json'}: names no data file; pass the recording "
                "(--data DATA.h5)"
            )
        path = Path(stored)
        if not path.is_absolute():
            path = run.path / path
        if not path.exists():
            raise EctskinError(
                f"{run.path / 'split.json'}: data file {path} no longer exists; pass --data DATA.h5"
            )
    else:
        path = Path(data)
    return read_recording(path), str(path)


def _test_case(run: Run, rec: Recording) -> tuple[EvalCase, dict[str, Any]]:
    """The run's data set of ``rec``, its split (ids) and the model's test predictions."""
    task = run.task
    ds = task.dataset(
        rec, reference=run.split.get("reference", "auto"), **task.dataset_options(run.config)
    )
    check_channels(run.model_file, run.config, ds.n_pairs)
    split = split_from_names(run.split, ds.group_names, source=str(run.path / "split.json"))
    test = ds.select(split["test"])
    if run.classical is not None:
        pred = run.classical.predict(test.x)
    else:
        pred = task.predict(run.model, test)
    return EvalCase(data=ds, test=test, pred=pred, recording=rec, config=run.config), split


def _candidates_on_test(run: Run, case: EvalCase, split: dict[str, Any]) -> dict[str, Any]:
    """Every candidate of candidates.json on the test split: {name: val_accuracy,
    test_accuracy, n_test_frames, n_misclassified, model (where it came from), selected}."""
    test, doc = case.test, run.candidates or {}
    train = None
    out: dict[str, Any] = {}
    for name, info in doc.get("candidates", {}).items():
        if name == run.selected:
            pred, source = case.pred, run.model_file.name
        elif name == "mlp":
            pred, source = run.task.predict(run.model, test), "model.pt"
        else:
            if train is None:
                train = case.data.select(split["train"])
            settings = info.get("settings") or {}
            with thread_limit(1):
                model, _, _ = fit_classical(
                    name,
                    train,
                    seed=int(settings.get("seed", 0)),
                    max_train=settings.get("max_train"),
                )
            pred, source = model.predict(test.x), "refit on the train split"
        wrong = int((pred != test.y).sum())
        out[name] = {
            "val_accuracy": info.get("val_accuracy"),
            "test_accuracy": accuracy(pred, test.y),
            "n_test_frames": int(test.n_samples),
            "n_misclassified": wrong,
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
