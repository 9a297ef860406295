"""Few-shot adaptation to a new skin: how many labelled frames of another skin a trained contact
run needs, against training from scratch and against k-NN and ridge on the same frames
(``ectskin study few-shot RUN NEW.h5 -o OUT``, :func:`few_shot_curve`).

The source is a trained contact run (``ectskin train contact``; its network, ``model.pt``); the
new skin is a labelled recording of a skin that differs physically (another layout, another
body) with the same pair count. The new recording's trials are split as ``ectskin train
contact NEW.h5 --seed SEED`` would split them (the task's trial fractions, stratified by
region): its **test** trials score every method, its **train** trials are the pool the labelled
frames are drawn from (its validation trials are not used).

For each draw (``draws``, default 3) a permutation of the pool's frames is drawn from
(``seed``, draw); the N labelled frames are its first N, for every N of ``frames`` (default
0, 100, 300, 1 000), so the draws are nested (the 100 frames lie inside the 300) and every
method gets exactly the same N frames:

==============  ========================================================================
``finetune``    the source run fine-tuned on them through the path of ``ectskin train
                contact NEW.h5 --init-from RUN``
                (:func:`ectskin.design.variability.finetune_run`: the source's config,
                normaliser and weights; the source weights kept unless an epoch beats them
                on validation). N = 0: the source run as it is.
``scratch``     ContactNet trained from a seeded initialisation on them (normaliser fit on
                them), the same settings otherwise.
``knn``         the contact task's k-NN (:mod:`ectskin.learn.contact_classical`), fit on
                all N frames.
``ridge``       ridge regression (logistic regression for the classes), likewise.
==============  ========================================================================

The networks hold out every ``val_every``-th of the N frames (in draw order, so the held-out
frames are nested too) to pick their kept epoch; the classical models fit on all N. Both
networks train with the contact ``profile`` (default ``quick``: Adam, the inflation shift,
the weights of the best validation point error) for about ``steps`` optimiser steps in batches
of ``batch_size`` (epochs = ⌈steps / batches per epoch⌉; the learning rate divided by 1.2
:data:`LR_DECAYS` times over them, as the profile's schedule), at ``finetune_lr`` and
``scratch_lr``.

Frames are calibrated (Eq. 2) against the new skin's own rest readout and read through the
source's window. Scores on the test trials, as the contact metrics compute them
(:func:`ectskin.learn.tasks.contact.contact_report`): ``loc_mm_mean`` (point error over the
skin, frames with one finger), ``force_mae_n`` and ``count_accuracy`` (:data:`METRICS`).
``OUT/few_shot.json`` holds per N and method each metric's mean, standard deviation and values
over the draws; ``OUT/few_shot.png`` the curves (:func:`ectskin.viz.variability.plot_few_shot`).

A new skin to try it on: :func:`simulate_new_skin` (``--simulate``) records the contact-style
protocol of :func:`new_skin_protocol` (method-of-moments solves) on :func:`new_skin_layout`, a
member of the layout family (:mod:`ectskin.design.family`) with wider-spread, longer and
wider wires than the paper's.

The same study for a touch run (``ectskin study few-shot-touch``) is
:mod:`ectskin.study.fewshot_touch`; it shares the draws, the networks' settings and the outputs
defined here.
"""

from __future__ import annotations

import argparse
import hashlib
import logging
import math
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ectskin._check import EctskinError, check_option, check_seed
from ectskin._files import save_figure_atomic, write_json_atomic

log = logging.getLogger(__name__)

HELP = (
    "few-shot curves on a new skin: a trained contact run fine-tuned on N labelled frames, "
    "against ContactNet from scratch and k-NN / ridge on the same frames"
)
EXAMPLES = """\
  ectskin study few-shot runs/contact new.h5 -o fewshot               # N = 0, 100, 300, 1000
  ectskin study few-shot runs/contact new.h5 -o fewshot --simulate    # record new.h5 first
  ectskin study few-shot runs/contact new.h5 -o fs --frames 0,50,200 --draws 5
"""

#: the methods compared (module docstring)
METHODS = ("finetune", "scratch", "knn", "ridge")
#: the metrics scored, and their axis labels
METRICS = {
    "loc_mm_mean": "point error (mm)",
    "force_mae_n": "force MAE (N)",
    "count_accuracy": "finger count accuracy",
}
#: learning-rate decays (÷ 1.2 each) over a network's training, as the quick contact profile
LR_DECAYS = 5
RESULT_FILE = "few_shot.json"
FIGURE_FILE = "few_shot.png"
FORMAT = "ectskin.few_shot"
VERSION = 1
#: the second word of the frame draws' seeds
DRAW_TAG = 0xF5


@dataclass(frozen=True)
class FewShotConfig:
    """What :func:`few_shot_curve` does (module docstring). ``counts``: the new recording's
    trial split (train, val, test), default the contact task's; ``threads``: torch threads of
    the trainings (default 1). :attr:`ALLOWED` the methods it knows."""

    ALLOWED: ClassVar[tuple[str, ...]] = METHODS

    frames: tuple[int, ...] = (0, 100, 300, 1000)
    draws: int = 3
    seed: int = 0
    methods: tuple[str, ...] = METHODS
    steps: int = 400
    batch_size: int = 32
    finetune_lr: float = 3e-4
    scratch_lr: float = 1e-3
    val_every: int = 5
    profile: str = "quick"
    counts: tuple[float, float, float] | None = None
    threads: int | None = None

    def __post_init__(self) -> None:
        v = self.val_every
        if isinstance(v, bool) or not isinstance(v, int) or v < 2:
            raise EctskinError(f"few-shot: val_every must be an integer >= 2, got {v!r}")
        if not self.frames:
            raise EctskinError("few-shot: frames must hold at least one N, got ()")
        for n in self.frames:
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 0:
                raise EctskinError(
                    f"few-shot: frames must be whole numbers >= 0, got {self.frames!r}"
                )
            if 0 < n < 2 * self.val_every:
                raise EctskinError(
                    f"few-shot: frames: N = {n} is too few; the networks hold out every "
                    f"{self.val_every}th frame for validation, so N must be 0 or at least "
                    f"{2 * self.val_every}"
                )
        if len(set(self.frames)) != len(self.frames):
            raise EctskinError(f"few-shot: frames must be distinct, got {self.frames!r}")
        for name in ("draws", "steps", "batch_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise EctskinError(f"few-shot: {name} must be an integer >= 1, got {v!r}")
        check_seed("seed", self.seed, source="few-shot")
        if not self.methods:
            raise EctskinError("few-shot: methods must name at least one method, got ()")
        for m in self.methods:
            check_option("method", m, self.ALLOWED, source="few-shot")
        for name in ("finetune_lr", "scratch_lr"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise EctskinError(f"few-shot: {name} must be a number > 0, got {v!r}")


# ----------------------------------------------------------------------------- the new skin
def new_skin_layout():
    """The new skin of the study: the layout family's member (:mod:`ectskin.design.family`)
    with 4 wires per face spread over 34 mm (the paper's: 30), 25 to 100 mm long (20 to 95),
    1.5 mm wide (1), pads straight below; the paper's skins, regions and markers."""
    from ectskin.design.family import FaceDesign, LayoutDesign, build_layout

    face = FaceDesign(span_mm=34.0, length_min_mm=25.0, length_max_mm=100.0, width_mm=1.5)
    return build_layout(LayoutDesign(face, face), "fewshot_wide")


def new_skin_protocol(seed: int = 0):
    """The contact-style protocol recorded on the new skin: the chambers at 0 and 20 ml (8
    states), per state a no-contact trial and 8 touch trials of 10 s, each pressing at 4
    points anywhere in its region with lifts, hover and approach, a second finger in 30 % of
    them; method-of-moments solves (``response="solve"``). 72 trials, 21 600 frames."""
    from ectskin.twin import Protocol

    return Protocol(
        levels_ml=(0.0, 20.0),
        touch_trials=8,
        duration_s=10.0,
        touch_placement="uniform",
        touch_dwells=4,
        dwell_slide_s=0.0,  # jumps from point to point, as when the study was measured
        lifts=True,
        hover=True,
        approach=True,
        second_finger=0.3,
        seed=seed,
    )


def simulate_new_skin(
    path: str | Path, *, seed: int = 0, workers: int | None = None, progress: bool = True
) -> Path:
    """Record :func:`new_skin_protocol` on :func:`new_skin_layout` in the twin into ``path``
    (HDF5; an existing file is refused)."""
    from ectskin.io import write_recording
    from ectskin.twin import simulate_experiment

    path = Path(path)
    if path.exists():
        raise EctskinError(f"{path}: exists; the new skin's recording is not replaced")
    rec = simulate_experiment(
        new_skin_protocol(seed), layout=new_skin_layout(), workers=workers, progress=progress
    )
    write_recording(rec, path)
    return path


# ----------------------------------------------------------------------------- the draws
def draw_frames(
    n_pool: int, frames: tuple[int, ...], draws: int, seed: int = 0
) -> list[dict[int, np.ndarray]]:
    """Per draw, N → the indices of the N frames drawn from a pool of ``n_pool``: the first N
    of one permutation seeded by (``seed``, draw), so the draws are nested in N. More frames
    than the pool holds is an error naming ``frames``."""
    too_many = [n for n in frames if n > n_pool]
    if too_many:
        raise EctskinError(
            f"few-shot: frames: N = {max(too_many)} is more than the {n_pool} frames of the new "
            "skin's training trials; choose N <= that, or record more trials"
        )
    out = []
    for d in range(draws):
        perm = np.random.default_rng([seed, DRAW_TAG, d]).permutation(n_pool)
        out.append({int(n): perm[:n] for n in frames})
    return out


def net_split(n: int, val_every: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions 0..n−1 of the drawn frames: (the networks' training, their validation), every
    ``val_every``-th validating (positions val_every − 1, 2 val_every − 1, ...)."""
    pos = np.arange(n)
    val = (pos % val_every) == val_every - 1
    return pos[~val], pos[val]


# ----------------------------------------------------------------------------- the study
def few_shot_curve(
    source_run: str | Path,
    new_data: Any,
    out: str | Path | None = None,
    config: FewShotConfig | None = None,
) -> dict[str, Any]:
    """The few-shot curves of ``source_run`` (a contact run folder) on ``new_data`` (a
    Recording or its file): see the module docstring. Writes ``out/few_shot.json`` and
    ``out/few_shot.png`` when ``out`` is given; returns what the JSON holds."""
    from ectskin.io import Recording, read_recording
    from ectskin.learn.splits import split_groups

    config = FewShotConfig() if config is None else config
    t0 = time.perf_counter()
    run = _source_run(source_run)
    task = run.task
    if isinstance(new_data, Recording):
        rec, data_desc = new_data, str(new_data.source or "given Recording")
    else:
        rec, data_desc = read_recording(new_data), str(new_data)
    ds = task.dataset(rec, **task.dataset_options(run.config))
    if ds.n_pairs != int(run.config.n_pairs):
        raise EctskinError(
            f"few-shot: new_data {data_desc}: {ds.n_pairs} pairs, the source run's model reads "
            f"{run.config.n_pairs}; the new skin needs the same pair count"
        )
    counts = config.counts or task.split_counts
    ids = split_groups(ds.group_names, counts, seed=config.seed, stratify=task.stratify(ds))
    pool, test = ds.select(ids["train"]), ds.select(ids["test"])
    draws = draw_frames(pool.n_samples, tuple(config.frames), config.draws, config.seed)
    base = _scores(test, task.predict(run.model, test))
    log.info(
        "few-shot: source %s on the new skin's %d test frames: %.2f mm, %.3f N, count %.3f",
        run.path,
        test.n_samples,
        base["loc_mm_mean"] or math.nan,
        base["force_mae_n"] or math.nan,
        base["count_accuracy"] or math.nan,
    )
    values, seconds = curve_values(
        draws, config, pool, base,
        lambda method, sample, d: _fit_predict(method, run, sample, test, config,
                                               seed=config.seed + d),
        lambda pred: _scores(test, pred),
        lambda d, n, method, v: log.info("few-shot draw %d, N = %d, %s: %.2f mm", d, n, method,
                                         v["loc_mm_mean"] or math.nan),
    )
    study = dict(task=task, run=run, rec=rec, data_desc=data_desc, config=config, counts=counts,
                 ds=ds, ids=ids, pool=pool, test=test, draws=draws, base=base)
    split = {"test_single_contact_frames": base["n_single_contact_frames"]}
    return curve_document(study, METRICS, values, seconds, t0, out, split=split)


def curve_document(
    study: dict[str, Any], metrics: dict[str, str], values: dict, seconds: dict, t0: float,
    out: str | Path | None, *, split: dict[str, Any], extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The study's document (``few_shot.json``), written to ``out`` when given: the source run,
    the new skin's data, the config, the split (plus ``split``), the draws, the source run's own
    scores, the curve (``values`` per N and method, summarised by :func:`draw_stats`), the
    fitting and total seconds (since ``t0``); ``extra`` top-level keys after ``new_layout``.
    ``study``: task, run, rec, data_desc, config, counts, ds, ids, pool, test, draws, base.
    Shared by the contact and touch studies."""
    s = study
    ds, pool = s["ds"], s["pool"]
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "task": s["task"].name,
        "source_run": str(Path(s["run"].path).resolve()),
        "source_data": s["run"].split.get("data"),
        "new_data": s["data_desc"],
        "new_layout": s["rec"].layout.name,
        **(extra or {}),
        "config": {**asdict(s["config"]), "counts": list(s["counts"])},
        "split": {
            "train": [ds.group_names[i] for i in s["ids"]["train"]],
            "test": [ds.group_names[i] for i in s["ids"]["test"]],
            "pool_frames": pool.n_samples,
            "test_frames": s["test"].n_samples,
            **split,
        },
        "draws": draw_records(pool, s["draws"], s["config"].seed),
        "metrics": dict(metrics),
        "source_on_new_skin": s["base"],
        "curve": {
            n: {m: draw_stats(v, metrics) for m, v in per.items() if v} for n, per in values.items()
        },
        "fit_seconds": seconds,
    }
    doc["seconds"] = time.perf_counter() - t0
    if out is not None:
        write_outputs(out, doc)
    return doc



def curve_values(draws, config, pool, base, fit_predict, score, report):
    """The curve's scores ({str(N): {method: [scores per draw]}}) and each method's fitting
    seconds: for every draw and N, each method fitted on the draw's N frames
    (``fit_predict(method, sample, draw)``) and scored (``score(pred)``); at N = 0 the source
    run's own ``base`` scores for "finetune" (nothing to fit). ``report(draw, N, method,
    scores)`` logs each. Shared by the contact and touch studies."""
    values: dict[str, dict[str, list[dict[str, Any]]]] = {
        str(n): {m: [] for m in config.methods} for n in config.frames
    }
    seconds: dict[str, float] = dict.fromkeys(config.methods, 0.0)
    for d, sets in enumerate(draws):
        for n in config.frames:
            sample = pool.take(sets[n])
            for method in config.methods:
                if n == 0:
                    if method == "finetune":
                        values["0"][method].append(base)
                    continue
                t1 = time.perf_counter()
                pred = fit_predict(method, sample, d)
                seconds[method] += time.perf_counter() - t1
                values[str(n)][method].append(score(pred))
                report(d, n, method, values[str(n)][method][-1])
    return values, seconds

def write_outputs(out: str | Path, doc: dict[str, Any]) -> dict[str, Path]:
    """``few_shot.json`` and ``few_shot.png`` of ``doc`` into ``out`` (atomically)."""
    from ectskin.viz.variability import plot_few_shot

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig = plot_few_shot(doc["curve"], doc["metrics"])
    paths = {"figure": save_figure_atomic(fig, out / FIGURE_FILE)}
    paths["json"] = write_json_atomic(out / RESULT_FILE, doc)
    log.info("wrote %s and %s", paths["json"], paths["figure"])
    return paths


def _source_run(source_run: str | Path):
    """The source run, read and checked: a contact run with a network."""
    from ectskin.learn.evaluate import read_run

    path = Path(source_run)
    if not path.is_dir():
        raise EctskinError(f"few-shot: source_run {path}: not a run folder")
    run = read_run(path)
    if run.task.name != "contact":
        raise EctskinError(
            f"few-shot: source_run {path}: field 'task' is {run.task.name!r}, expected "
            "'contact' (a run of ectskin train contact; a touch run: ectskin study few-shot-touch)"
        )
    if run.model is None:
        raise EctskinError(
            f"few-shot: source_run {path}: field 'model' is a classical model alone "
            f"({run.selected}); fine-tuning needs the run's network (model.pt)"
        )
    return run


def net_config(config: FewShotConfig, n_train: int, lr: float, seed: int):
    """The networks' TrainConfig for ``n_train`` training frames (module docstring)."""
    from ectskin.learn.profiles import TrainConfig

    epochs = max(1, math.ceil(config.steps / math.ceil(n_train / config.batch_size)))
    return TrainConfig(
        profile=config.profile,
        seed=seed,
        epochs=epochs,
        batch_size=config.batch_size,
        settings={
            "lr": lr,
            "step_size": max(1, epochs // LR_DECAYS),
            "samples_per_epoch": None,
            "val_samples": None,
        },
        threads=config.threads,
        progress=False,
        resume=False,
    )


def _fit_predict(method: str, run, sample, test, config: FewShotConfig, *, seed: int):
    """``method`` fit on the drawn frames ``sample``; its predictions on ``test``."""
    if method in ("knn", "ridge"):
        from ectskin.learn.contact_classical import fit_contact_classical

        classical, _, _ = fit_contact_classical(method, sample, seed=seed)
        return classical.predict(test.x)
    from ectskin.design.variability import finetune_run
    from ectskin.learn.checkpoint import load_checkpoint
    from ectskin.learn.train import train

    tr, va = net_split(sample.n_samples, config.val_every)
    train_data, val_data = sample.take(tr), sample.take(va)
    if method == "finetune":
        cfg = net_config(config, len(tr), config.finetune_lr, seed)
        model, _ = finetune_run("contact", run.path, train_data, val_data, cfg)
    else:
        cfg = net_config(config, len(tr), config.scratch_lr, seed)
        with tempfile.TemporaryDirectory(prefix="ectskin-scratch-") as folder:
            train("contact", train_data, val_data, folder, cfg)
            model, _, _ = load_checkpoint(Path(folder) / "model.pt", kind=run.task.model_kind)
        model.eval()
    return run.task.predict(model, test)


def _scores(test, pred: np.ndarray) -> dict[str, Any]:
    from ectskin.learn.tasks.contact import contact_report

    m = contact_report(test, pred, with_maps=False)
    out = {k: (None if m[k] is None else float(m[k])) for k in (*METRICS, "loc_mm_median")}
    return {**out, "n_single_contact_frames": int(m["n_single_contact_frames"])}


def draw_stats(runs: list[dict[str, Any]], metrics: dict[str, str]) -> dict[str, Any]:
    """Per metric of ``metrics``: mean, standard deviation (ddof 0) and the values over the
    draws (None where a draw has none)."""
    out = {}
    for key in metrics:
        vals = [r[key] for r in runs]
        ok = [v for v in vals if v is not None]
        out[key] = {
            "mean": float(np.mean(ok)) if ok else None,
            "std": float(np.std(ok)) if ok else None,
            "values": vals,
        }
    return out


def draw_records(pool, draws: list[dict[int, np.ndarray]], seed: int) -> list[dict[str, Any]]:
    """Per draw: its seed and, per N, the digest of its frames (:func:`frames_digest`)."""
    return [
        {"seed": [seed, DRAW_TAG, d], "frames": {str(n): frames_digest(pool, s[n]) for n in s}}
        for d, s in enumerate(draws)
    ]


def frames_digest(pool, idx: np.ndarray) -> str:
    """A short digest of the drawn frames (trial name and frame of each, in draw order); data
    without a ``frame`` field (touch) count each sample's place among its trial's samples."""
    frame = getattr(pool, "frame", None)
    if frame is None:
        group = np.asarray(pool.group)
        frame = np.empty(group.size, np.int64)
        for g in np.unique(group):
            rows = np.flatnonzero(group == g)
            frame[rows] = np.arange(rows.size)
    h = hashlib.sha256()
    for i in idx:
        h.update(f"{pool.group_names[pool.group[i]]}:{int(frame[i])};".encode())
    return h.hexdigest()[:16]


# ----------------------------------------------------------------------------- the command
def add_arguments(p: argparse.ArgumentParser) -> None:
    common_arguments(p, "contact", METHODS)


def common_arguments(p: argparse.ArgumentParser, task: str, methods: tuple[str, ...]) -> None:
    """The options of ``ectskin study few-shot`` (``task`` "contact") and ``few-shot-touch``."""
    p.add_argument("run", help=f"the source: a trained {task} run folder (ectskin train {task})")
    p.add_argument("data", help="the new skin's labelled recording (HDF5), same pair count")
    p.add_argument("-o", "--out", required=True, help="output folder (few_shot.json, few_shot.png)")
    p.add_argument(
        "--frames", default="0,100,300,1000", help="the N of the curve (default 0,100,300,1000)"
    )
    p.add_argument("--draws", type=int, default=3, help="frame draws per N (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the split and the draws")
    p.add_argument(
        "--methods", default=",".join(methods), help=f"methods (default {','.join(methods)})"
    )
    p.add_argument(
        "--steps", type=int, default=400, help="optimiser steps per network (default 400)"
    )
    p.add_argument("--threads", type=int, default=None, help="torch threads (default 1)")
    p.add_argument(
        "--simulate",
        action="store_true",
        help="first record DATA in the twin with the study's new skin (fewshot_wide layout, "
        "contact-style protocol) if it does not exist",
    )
    p.add_argument("--workers", type=int, default=None, help="simulation processes (--simulate)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    return run_study(args, FewShotConfig, few_shot_curve)


def run_study(args: argparse.Namespace, config_type: type[FewShotConfig], curve: Any) -> int:
    """The command: the options checked (``config_type``) before any work, the new skin
    recorded with ``--simulate``, then ``curve(run, data, out, config)`` and its summary."""
    from ectskin._check import parse_floats

    frames = parse_floats("--frames", args.frames)
    if any(f != int(f) for f in frames):
        raise EctskinError(f"--frames must be whole frame counts, got {args.frames!r}")
    methods = tuple(m.strip() for m in str(args.methods).split(",") if m.strip())
    config = config_type(
        frames=tuple(int(f) for f in frames),
        draws=args.draws,
        seed=args.seed,
        methods=methods,
        steps=args.steps,
        threads=args.threads,
    )
    if args.simulate and not Path(args.data).exists():
        simulate_new_skin(
            args.data, seed=args.seed, workers=args.workers, progress=not args.no_progress
        )
    doc = curve(args.run, args.data, args.out, config)
    for line in summary_lines(doc):
        log.info("%s", line)
    return 0


def summary_lines(doc: dict[str, Any]) -> list[str]:
    """The curve as text lines: per N and method, each metric's mean ± std."""
    lines = []
    for n, per in doc["curve"].items():
        for method, s in per.items():
            cells = [
                f"{key} {s[key]['mean']:.3f} ± {s[key]['std']:.3f}"
                for key in doc["metrics"]
                if s[key]["mean"] is not None
            ]
            lines.append(f"N = {n:>5} {method:<9} " + ", ".join(cells))
    return lines
