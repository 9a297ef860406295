"""The files of a run directory, written by training and read by evaluation and resume::

    out_dir/model.pt      best-validation weights (a checkpoint, see ectskin.learn.checkpoint)
    out_dir/last.pt       the same plus optimizer, scheduler and epoch, to resume
    out_dir/metrics.csv   epoch, train_loss, val_loss, val_metric, lr, seconds
    out_dir/config.json   task, profile, training settings, recipe, model config, data sizes
    out_dir/split.json    trial (group) names per split (+ task, data file, counts, split seed,
                          the recording's trial digests and rest reference: :func:`data_identity`)
    out_dir/metrics.json  test-set metrics (written by ``ectskin evaluate``; on other data
                          metrics_<data stem>.json), with the figures (.png, .pdf or .svg)

Each file has one writer and one reader here: :func:`write_metrics` / :func:`read_metrics`,
:func:`write_run_config` / :func:`read_run_config`, :func:`read_split`. Every problem with a file
is one :class:`EctskinError` naming the file, what was expected and what was found.
"""

from __future__ import annotations

import csv
import hashlib
import io
import logging
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin._files import atomic_write, read_json_object, to_jsonable, write_json_atomic
from ectskin.io.calibration import own_reference, rest_reference
from ectskin.io.recording import Recording
from ectskin.learn.channels import measured_channels
from ectskin.learn.checkpoint import config_from_dict, read_checkpoint
from ectskin.learn.distributed import Dist
from ectskin.learn.profiles import TrainSettings
from ectskin.learn.splits import trial_digests

log = logging.getLogger(__name__)

METRICS_COLUMNS = ("epoch", "train_loss", "val_loss", "val_metric", "lr", "seconds")
#: Files of a run directory; an existing folder holding anything else is not silently reused
#: (besides these: evaluations on other data, ``metrics_<data stem>.json``, and figures).
RUN_FILES = frozenset(
    {"model.pt", "last.pt", "metrics.csv", "config.json", "split.json", "metrics.json"}
    | {"candidates.json", "model.skops"}  # the touch model choice (ectskin.learn.candidates)
)
#: suffixes of the figures an evaluation writes into a run directory
FIGURE_SUFFIXES = frozenset({".png", ".pdf", ".svg"})


# --------------------------------------------------------------------------- metrics.csv
def write_metrics(path: str | Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write the per-epoch rows (:data:`METRICS_COLUMNS`) to ``path`` atomically."""
    text = io.StringIO(newline="")
    w = csv.DictWriter(text, fieldnames=METRICS_COLUMNS)
    w.writeheader()
    for r in rows:
        w.writerow({k: r[k] for k in METRICS_COLUMNS})
    data = text.getvalue().encode("utf-8")
    return atomic_write(path, lambda fh: fh.write(data))


def read_metrics(path: str | Path) -> list[dict[str, float]]:
    """Rows of a run's ``metrics.csv`` as dicts of numbers (epoch as int)."""
    path = Path(path)
    if not path.is_file():
        raise EctskinError(f"{path}: no metrics file")
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    try:
        return [
            {k: (int(r[k]) if k == "epoch" else float(r[k])) for k in METRICS_COLUMNS} for r in rows
        ]
    except (KeyError, TypeError, ValueError) as exc:
        raise EctskinError(f"{path}: malformed metrics file ({exc})") from None


# --------------------------------------------------------------------------- config.json
def write_run_config(path: str | Path, config: Mapping[str, Any]) -> Path:
    """Write a run's ``config.json`` (strict JSON, atomically)."""
    return write_json_atomic(path, config)


def read_run_config(run_dir: str | Path, task: str) -> dict[str, Any] | None:
    """The run's ``config.json`` (written by training), checked; None when the run has none.

    The file must hold a JSON object whose ``task`` is ``task`` (the task of the run's model),
    with ``settings`` and ``recipe`` objects where present; anything else is an EctskinError
    naming the file, what was expected and what was found.
    """
    path = Path(run_dir) / "config.json"
    if not path.exists():
        return None
    cfg = read_json_object(path, "run config")
    found = cfg.get("task")
    if found != task:
        what = "no field 'task'" if "task" not in cfg else f"task {found!r}"
        raise EctskinError(
            f"{path}: expected the config of a {task!r} run (the task of model.pt), found {what}"
        )
    for key in ("settings", "recipe"):
        value = cfg.get(key)
        if value is not None and not isinstance(value, dict):
            raise EctskinError(
                f"{path}: field {key!r} must be a JSON object, found a JSON {type(value).__name__}"
            )
    return cfg


# --------------------------------------------------------------------------- split.json
def read_split(run_dir: str | Path) -> dict[str, Any]:
    """Read and check ``run_dir/split.json``: train / val / test trial names (+ data settings)."""
    path = Path(run_dir) / "split.json"
    info = read_json_object(path, "split file")
    for key in ("train", "val", "test"):
        names = info.get(key)
        if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
            raise EctskinError(f"{path}: field {key!r} must be a list of trial names")
    if not info["test"]:
        raise EctskinError(f"{path}: the test split is empty; nothing to evaluate")
    return info


def data_identity(rec: Recording) -> dict[str, Any]:
    """What ``split.json`` stores about the training recording beside the split:
    ``trial_digests`` (:func:`trial_digests`) and, when the recording calibrates against a rest
    state (:func:`ectskin.io.calibration.own_reference`), ``rest_reference``: that reference
    (pF per pair of the layout, null for an unmeasured one), the pair names and the rest-state
    trials it averages, so that evaluation can calibrate a recording without a rest state of its
    own (:func:`stored_rest_reference`)."""
    out: dict[str, Any] = {"trial_digests": trial_digests(rec)}
    if own_reference(rec) == "rest":
        keep = measured_channels(rec)
        try:
            ref, trials = rest_reference(rec, channels=keep)
        except EctskinError as exc:  # a task that does not calibrate against it (tracking)
            log.info("no rest reference stored in the run: %s", exc)
            return out
        full = np.full(rec.n_pairs, np.nan)
        full[keep] = ref
        out["rest_reference"] = {
            "pF": [float(v) if np.isfinite(v) else None for v in full],
            "pair_names": list(rec.layout.pair_names),
            "trials": trials,
        }
    return out


def stored_rest_reference(
    split: Mapping[str, Any], pair_names: Sequence[str], source: str
) -> tuple[np.ndarray, list[str]] | None:
    """``split.json``'s ``rest_reference`` as an (n_pairs,) float64 array in the order of
    ``pair_names`` (NaN for an unmeasured pair) with its rest-state trials; None when the run
    stores none. A reference of other pairs is an error naming the file."""
    doc = split.get("rest_reference")
    if doc is None:
        return None
    try:
        values = np.array([np.nan if v is None else v for v in doc["pF"]], dtype=np.float64)
        names = [str(n) for n in doc["pair_names"]]
        trials = [str(t) for t in doc.get("trials", [])]
    except (KeyError, TypeError, ValueError):
        raise EctskinError(
            f"{source}: field 'rest_reference' must hold 'pF' (numbers) and 'pair_names'"
        ) from None
    if values.shape != (len(names),) or names != list(pair_names):
        raise EctskinError(
            f"{source}: the stored rest reference is of pairs {names[:3]}... ({len(names)}), "
            f"the recording has {list(pair_names)[:3]}... ({len(pair_names)})"
        )
    return values, trials


def split_names_of(data: Any) -> list[str]:
    """The names of the trials (groups) present in ``data``, in group order."""
    names = list(getattr(data, "group_names", []) or [])
    group = getattr(data, "group", None)
    if group is None or not names:
        return []
    return [str(names[g]) for g in np.unique(group) if 0 <= g < len(names)]


# --------------------------------------------------------------------------- the folder
def check_run_folder(out: str | Path, *, resume: bool) -> None:
    """Refuse an output folder that is not a run directory (unless ``resume`` is False, which
    starts over), or a run that cannot be resumed (model.pt without last.pt)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise EctskinError(f"output folder {out} exists and is not a folder")
    if not out.is_dir() or not resume:
        return
    others = sorted(p.name for p in out.iterdir() if not _belongs_to_a_run(p.name))
    if others:
        raise EctskinError(
            f"output folder {out} is a non-empty folder that is not a run directory (holds "
            f"{', '.join(others[:5])}); choose another folder, or start over with --overwrite"
        )
    if (out / "model.pt").exists() and not (out / "last.pt").exists():
        raise EctskinError(
            f"output folder {out} holds a model.pt without last.pt (cannot resume); start over "
            "with --overwrite to train again"
        )


def check_run_dir(run: Path) -> None:
    """A run directory to read that is a file (a recording, say) or is missing: one clear
    error saying what ``evaluate`` expects."""
    if run.exists() and not run.is_dir():
        raise EctskinError(
            f"{run} is a file, not a run directory: evaluate expects the folder 'ectskin train' "
            f"wrote (model.pt, split.json, ...); a recording goes with --data (ectskin evaluate "
            f"RUN_DIR --data {run})"
        )
    if not run.is_dir():
        raise EctskinError(f"run directory {run} does not exist")


def evaluation_inputs(run_dir: Any, data: Any, reference: Any, out: Any) -> dict[Path, str]:
    """Check an evaluation's paths before any work: the run directory is a folder
    (:func:`check_run_dir`), the recordings given (``data``, ``reference``: paths; anything
    else is taken as in memory) are files, and ``out`` is a folder that is none of the inputs.
    Returns {input file (resolved): what it is}."""
    run = Path(run_dir)
    check_run_dir(run)
    inputs: dict[Path, str] = {}
    for name in sorted(RUN_FILES - {"metrics.json"}):  # metrics.json is evaluate's own output
        if (run / name).exists():
            inputs[(run / name).resolve()] = f"the run's {name}"
    for option, value in (("--data", data), ("--reference", reference)):
        if not isinstance(value, str | os.PathLike):
            continue
        path = Path(value)
        if not path.is_file():
            what = "is a folder" if path.is_dir() else "does not exist"
            raise EctskinError(f"{option} {path} {what}; expected a recording file")
        inputs[path.resolve()] = f"the recording given with {option}"
    if out is not None:
        folder = Path(out)
        if folder.resolve() in inputs:
            raise EctskinError(
                f"-o/--out {folder} is {inputs[folder.resolve()]}; expected a folder for the "
                "metrics JSON and the figures (nothing that is read is written over)"
            )
        if folder.exists() and not folder.is_dir():
            raise EctskinError(
                f"-o/--out {folder} is a file; expected a folder for the metrics JSON and the "
                "figures"
            )
    return inputs


def check_outputs(outputs: Sequence[Path], inputs: Mapping[Path, str]) -> None:
    """Refuse an output file that is one of the inputs (:func:`evaluation_inputs`)."""
    for path in outputs:
        if path.resolve() in inputs:
            raise EctskinError(
                f"{path} is {inputs[path.resolve()]} and would be written over by the "
                "evaluation; choose another folder with -o/--out"
            )


def _belongs_to_a_run(name: str) -> bool:
    """A file a run directory holds: its files, evaluations, figures, hidden files."""
    path = Path(name)
    return (
        name in RUN_FILES
        or name.startswith(".")
        or path.suffix in FIGURE_SUFFIXES
        or (name.startswith("metrics_") and path.suffix == ".json")
    )


def fingerprint(*arrays: np.ndarray) -> str:
    """A short hash of the training arrays, to refuse resuming on different data."""
    h = hashlib.blake2b(digest_size=12)
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def check_resumable(
    path: Path,
    payload: dict,
    state: dict,
    *,
    task: str,
    model_kind: str,
    model_config: Any,
    settings: TrainSettings,
    seed: int,
    data_fingerprint: str,
) -> None:
    """Refuse to resume a run trained with other settings, another model or other data."""
    hint = "use another output folder, or start over with --overwrite"
    if state.get("task") != task or payload["kind"] != model_kind:
        raise EctskinError(
            f"{path}: holds a {state.get('task')!r} run ({payload['kind']!r} model), not a "
            f"{task!r} run; {hint}"
        )
    old_cfg = asdict(config_from_dict(payload["kind"], payload["config"], path))
    new_cfg = asdict(model_config)
    diff = [k for k in new_cfg if old_cfg.get(k) != new_cfg[k]]
    if diff:
        detail = ", ".join(f"{k} {old_cfg.get(k)!r} -> {new_cfg[k]!r}" for k in diff)
        raise EctskinError(f"{path}: the model differs from the saved one ({detail}); {hint}")
    # runs saved before a setting existed were trained with its default
    defaults = {f.name: f.default for f in fields(TrainSettings) if f.default is not MISSING}
    old = {**to_jsonable(defaults), **dict(state.get("settings") or {})}
    new = to_jsonable(asdict(settings))
    diff = [k for k in new if k != "epochs" and old.get(k) != new[k]]
    if diff:
        detail = ", ".join(f"{k} {old.get(k)!r} -> {new[k]!r}" for k in diff)
        raise EctskinError(f"{path}: training settings differ ({detail}); {hint}")
    if int(state.get("seed", seed)) != seed:
        raise EctskinError(f"{path}: was trained with seed {state.get('seed')}, not {seed}; {hint}")
    if state.get("data_fingerprint") != data_fingerprint:
        raise EctskinError(f"{path}: was trained on different training data; {hint}")


# --------------------------------------------------------------------------- resume
@dataclass
class RunState:
    """Where training stands: the epochs done, the kept weights' epoch and scores, the rows of
    metrics.csv and the seconds spent before this call (a resumed run)."""

    epoch: int = 0
    best_loss: float = math.inf
    best_metric: float = math.nan
    best_epoch: int = 0
    seconds_before: float = 0.0
    resumed_from: int = 0
    rows: list[dict[str, Any]] = field(default_factory=list)


def resume_run(
    out_dir: Path,
    *,
    resume: bool,
    model: Any,
    optimizer: Any,
    scheduler: Any,
    task: str,
    settings: TrainSettings,
    seed: int,
    data_fingerprint: str,
    d: Dist,
) -> RunState:
    """The state of the run in ``out_dir/last.pt`` with the model's weights, the optimizer and
    the scheduler restored from it (after :func:`check_resumable`), or a fresh state (no
    ``last.pt``, or ``resume`` False). metrics.csv rows written after last.pt (a crash in
    between) are dropped."""
    path = out_dir / "last.pt"
    if not (resume and path.exists()):
        if path.exists() and d.main:
            log.warning("%s exists; starting over (--overwrite)", path)
        return RunState()
    payload = read_checkpoint(path, map_location=d.device)
    saved = payload.get("resume")
    if not isinstance(saved, dict):
        raise EctskinError(f"{path}: holds no training state to resume from")
    check_resumable(
        path,
        payload,
        saved,
        task=task,
        model_kind=model.kind,
        model_config=model.config,
        settings=settings,
        seed=seed,
        data_fingerprint=data_fingerprint,
    )
    model.load_state_dict(payload["state_dict"])
    optimizer.load_state_dict(saved["optimizer"])
    scheduler.load_state_dict(saved["scheduler"])
    epoch = int(saved["epoch"])
    metrics_path = out_dir / "metrics.csv"
    rows = read_metrics(metrics_path) if metrics_path.exists() else []
    if d.main:
        if epoch >= settings.epochs:
            msg = "%s: already trained %d epochs (asked for %d); nothing to do"
            log.info(msg, path, epoch, settings.epochs)
        else:
            log.info(
                "%s: resuming %s training after epoch %d of %d", path, task, epoch, settings.epochs
            )
    return RunState(
        epoch=epoch,
        best_loss=float(saved["best_val_loss"]),
        best_metric=float(saved["best_val_metric"]),
        best_epoch=int(saved["best_epoch"]),
        seconds_before=float(saved["seconds"]),
        resumed_from=epoch,
        rows=[r for r in rows if r["epoch"] <= epoch],
    )


# --------------------------------------------------------------------------- summary
def training_summary(
    rows: Sequence[Mapping[str, float]],
    run_config: Mapping[str, Any] | None = None,
    kept: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Epochs, best epoch and total time of a run from its ``metrics.csv`` rows.

    The best epoch, validation loss and metric are those of the kept weights, read from the
    checkpoint's metadata (``kept``: its ``extra``, written by training with ``epoch``,
    ``val_loss``, ``val_metric``), so they follow whatever rule chose them; without that
    metadata, the epoch of the lowest validation loss (the paper's rule). The run's selection
    rule and ``recipe`` (``run_config``, its config.json) are passed on when present.
    ``history`` holds the epoch, train_loss and val_loss columns (for the learning curves).
    Empty without rows.
    """
    if not rows:
        return {}

    def col(name: str) -> np.ndarray:
        return np.array([float(r[name]) for r in rows])

    out: dict[str, Any] = {}
    if run_config:
        out["select"] = (run_config.get("settings") or {}).get("select", "val_loss")
        if isinstance(run_config.get("recipe"), dict):
            out["recipe"] = run_config["recipe"]
    kept = kept or {}
    if all(k in kept for k in ("epoch", "val_loss", "val_metric")):
        best = {
            "best_epoch": int(kept["epoch"]),
            "best_val_loss": _number(kept["val_loss"]),
            "best_val_metric": _number(kept["val_metric"]),
        }
    else:
        val = col("val_loss")
        i = int(np.nanargmin(val)) if np.isfinite(val).any() else len(rows) - 1
        best = {
            "best_epoch": int(rows[i]["epoch"]),
            "best_val_loss": float(val[i]),
            "best_val_metric": float(rows[i]["val_metric"]),
        }
    return {
        **out,
        "epochs": len(rows),
        **best,
        "seconds": float(np.nansum(col("seconds"))),
        "history": {k: col(k).tolist() for k in ("epoch", "train_loss", "val_loss")},
    }


def _number(value: Any) -> float:
    """A stored number as float; None (a non-finite value under the JSON policy) as NaN."""
    return math.nan if value is None else float(value)
