"""How a model trained on the nominal skin fares on the skins that come out of the mould, and
what recovers it: :func:`run_variability` (``ectskin variability OUT``).

Steps (each cached under ``OUT``, so a stopped run resumes where it stopped):

1. **Simulate** one protocol (:data:`DEFAULT_PROTOCOL`, small: 8 inflation states, 6 short
   touch trials each, touches anywhere in their region) on the nominal skin, on ``skins``
   fabricated skins (:func:`~ectskin.twin.fabrication.sample_skin`) whose spreads are the
   variation × a scale running over ``scale_range`` (the x-axis of the degradation curves), on
   the nominal skin with a dead electrode and with a short (the fault cases), and on
   ``dr_skins`` more skins at scale 1 for domain randomisation. Every skin runs the same
   protocol with the same seed: the same touches, so the differences are the skin's.
   ``OUT/data/<skin>.h5``.
2. **Train** the touch (TouchMLP) and contact (ContactNet) models on the nominal recording
   (contact: ``profile``, default ``quick``; touch: ``touch_profile``, default ``robust``, the
   paper's TouchMLP with the recipe for unseen (inflation state, placement) combinations: this
   protocol has only a few touches per region, and the ``quick`` recipe's TouchMLP falls back to
   the no-touch class on it): ``OUT/runs/{touch,contact}_nominal``.
3. **Domain randomisation**: the same models trained on the nominal skin and the ``dr_skins``
   skins together, every frame calibrated against the *nominal* rest reference (the one a model
   in the field would use without a rest readout of its skin), on the trials of the nominal
   run's train and validation splits: ``OUT/runs/{touch,contact}_dr``.
4. **Evaluate** on the test trials of the nominal split (the same trial names on every skin):

   * ``baseline``: the nominal model, frames calibrated against the nominal skin's rest readout;
   * ``own_reference`` (recovery b): the nominal model, each skin's frames calibrated against
     its own rest readout (Eq. 2 with that skin's rest state). Not defined for a dead
     electrode, nor for a short (the shorted pair itself): those channels read noise around 0
     at rest (below :data:`DEAD_FRACTION` of the nominal readout), and Eq. 2 divides by them
     (null, with the reason);
   * ``domain_randomisation`` (recovery a): the DR model, nominal reference; and
     ``dr_own_reference``: the DR model with the skin's own reference;
   * ``finetune`` (recovery c): the nominal model fine-tuned on N labelled samples of the skin
     (N in ``finetune_frames``; drawn at random from its train-split trials, nominal
     reference, so N = 0 is the baseline) through the path of ``ectskin train --init-from``
     (:func:`finetune_run`: the nominal run's config, normaliser and weights), with
     :func:`finetune_config`: ``finetune_epochs`` epochs of Adam at a constant ``finetune_lr``,
     batches of :data:`FINETUNE_BATCH`, no augmentation; the N samples are also the validation
     data, so the kept weights are those of the lowest loss on them, the nominal weights
     (epoch 0) included.

   Touch: test accuracy; contact: ``loc_mm_mean`` (mm over the skin, frames with one finger).
   ``OUT/eval/<skin>.json`` per skin.
5. ``OUT/variability.json``, the figures ``OUT/variability_curves.png`` (metric against the
   perturbation scale, per recovery) and ``OUT/variability_finetune.png`` (metric against N),
   drawn by :mod:`ectskin.viz.variability`, and ``OUT/variability.md`` (its tables through the
   report's :func:`~ectskin.report.render.markdown_table`).

The perturbation of each skin is also measured: ``rest_deviation_pct``, the RMS over pairs of
the relative change of its rest readout from the nominal one.
"""

from __future__ import annotations

import contextlib
import logging
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ectskin._check import EctskinError
from ectskin._files import (
    read_json_object,
    save_figure_atomic,
    write_json_atomic,
    write_text_atomic,
)
from ectskin.io import Recording, read_recording, write_recording
from ectskin.io.calibration import touch_reference
from ectskin.layout import SensorLayout, default_layout
from ectskin.learn.checkpoint import load_checkpoint
from ectskin.learn.data import SampleData
from ectskin.learn.evaluate import Run, read_run
from ectskin.learn.tasks import EvalCase, get_task
from ectskin.learn.threads import torch_threads
from ectskin.learn.train import TrainConfig, train, train_from_recording
from ectskin.report.render import markdown_table
from ectskin.twin.fabrication import (
    FabricatedSkin,
    FabricationVariation,
    apply_fault,
    nominal_skin,
    sample_skin,
    simulate_skin,
)
from ectskin.twin.protocol import Protocol
from ectskin.viz.variability import plot_degradation, plot_finetune

log = logging.getLogger(__name__)

#: The tasks scored, and the metric of each (higher is better for accuracy, lower for mm).
TASKS = {"touch": "accuracy", "contact": "loc_mm_mean"}
#: The evaluations without fine-tuning: (name, model run, reference).
EVALUATIONS = (
    ("baseline", "nominal", "nominal"),
    ("own_reference", "nominal", "own"),
    ("domain_randomisation", "dr", "nominal"),
    ("dr_own_reference", "dr", "own"),
)

#: The batch size of the fine-tunes (recovery c).
FINETUNE_BATCH = 32

#: A channel whose own rest readout is below this fraction of the nominal one is dead.
DEAD_FRACTION = 0.01

#: The default protocol: small enough for a 2-core machine, with every region touched.
DEFAULT_PROTOCOL = Protocol(
    levels_ml=(0.0, 20.0),
    touch_trials=6,
    duration_s=4.0,
    touch_placement="uniform", touch_dwells=1,  # one point per trial, as when it was made
    force_nodes=3,
    seed=0,
)


@dataclass(frozen=True)
class VariabilityConfig:
    """What :func:`run_variability` does (module docstring).

    ``skins``: fabricated skins on the degradation curve, their spreads the variation ×
    scales evenly spaced over ``scale_range``; ``dr_skins``: skins (scale 1) added to the
    domain-randomisation training; ``finetune_frames``: the N of the fine-tuning curve (0 = no
    fine-tuning); ``profile``, ``touch_profile``: the training profiles of the contact and the
    touch models; ``epochs``: override the profile's training epochs; ``faults``: also score
    the nominal skin with a dead and with a shorted electrode; ``workers``: simulation
    processes; ``threads``: torch threads.
    """

    skins: int = 4
    seed: int = 0
    scale_range: tuple[float, float] = (0.5, 2.0)
    dr_skins: int = 2
    finetune_frames: tuple[int, ...] = (0, 100, 1000)
    finetune_epochs: int = 10
    finetune_lr: float = 3e-4
    faults: bool = True
    profile: str = "quick"
    touch_profile: str = "robust"
    epochs: int | None = None
    variation: FabricationVariation = field(default_factory=FabricationVariation)
    protocol: Protocol = DEFAULT_PROTOCOL
    layout: SensorLayout | None = None
    workers: int | None = None
    threads: int | str | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        for name in ("skins", "dr_skins", "finetune_epochs"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise EctskinError(f"variability: {name} must be an integer >= 0, got {v!r}")
        lo, hi = self.scale_range
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo <= hi):
            raise EctskinError(
                f"variability: scale_range must be 0 <= low <= high, got {self.scale_range!r}"
            )
        if any(
            isinstance(n, bool) or not isinstance(n, int) or n < 0 for n in self.finetune_frames
        ):
            raise EctskinError(
                f"variability: finetune_frames must be integers >= 0, got {self.finetune_frames!r}"
            )
        if not (np.isfinite(self.finetune_lr) and self.finetune_lr > 0):
            raise EctskinError(f"variability: finetune_lr must be > 0, got {self.finetune_lr!r}")

    def scales(self) -> np.ndarray:
        """(skins,) perturbation scales of the curve's skins."""
        if self.skins == 1:
            return np.array([self.scale_range[1]])
        return np.linspace(self.scale_range[0], self.scale_range[1], self.skins)


@dataclass(frozen=True)
class SkinCase:
    """One skin of the study: its name, role ("nominal", "sampled", "fault", "dr"), scale and
    the fabricated skin."""

    name: str
    role: str
    scale: float
    skin: FabricatedSkin


def skin_cases(config: VariabilityConfig) -> list[SkinCase]:
    """Every skin of the study, in order; seeds derived from ``config.seed``."""
    layout = config.layout or default_layout()
    base = config.seed * 1000
    cases = [SkinCase("nominal", "nominal", 0.0, nominal_skin(layout))]
    for k, s in enumerate(config.scales()):
        skin = sample_skin(layout, config.variation.scaled(float(s)), base + 1 + k)
        cases.append(SkinCase(f"skin{k + 1}", "sampled", float(s), skin))
    if config.faults:
        for kind in ("dead", "short"):
            v = replace(FabricationVariation.none(), fault=kind)
            cases.append(SkinCase(kind, "fault", 0.0, sample_skin(layout, v, base + 500)))
    for m in range(config.dr_skins):
        skin = sample_skin(layout, config.variation, base + 100 + m)
        cases.append(SkinCase(f"dr{m + 1}", "dr", 1.0, skin))
    return cases


# ----------------------------------------------------------------------------- the steps
def run_variability(out: str | Path, config: VariabilityConfig = VariabilityConfig()) -> dict:
    """Run the study (module docstring) into ``out``; returns what ``variability.json`` holds."""
    out = Path(out)
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    cases = skin_cases(config)
    recs: dict[str, Recording] = {}
    for c in cases:
        recs[c.name] = _simulated(out, c, config, recs.get("nominal"))
    nominal = recs["nominal"]
    nom_ref = _rest_reference(nominal)
    runs = {}
    for task in TASKS:
        runs[(task, "nominal")] = _train_nominal(out, task, config)
        split = read_run(runs[(task, "nominal")]).split
        dr = [recs["nominal"]] + [recs[c.name] for c in cases if c.role == "dr"]
        runs[(task, "dr")] = _train_dr(out, task, dr, nom_ref, split, config)
    results = {}
    for c in cases:
        if c.role == "dr":
            continue
        results[c.name] = _evaluated(out, c, recs[c.name], nom_ref, runs, config)
    doc = {
        "config": _config_dict(config),
        "skins": results,
        "summary": summarise(results),
        "seconds": time.perf_counter() - t0,
    }
    doc["figures"] = _figures(out, results, config)
    write_json_atomic(out / "variability.json", doc)
    write_text_atomic(out / "variability.md", report_markdown(doc))
    log.info("wrote %s and %s", out / "variability.json", out / "variability.md")
    return doc


def _simulated(
    out: Path, case: SkinCase, config: VariabilityConfig, nominal: Recording | None
) -> Recording:
    """The recording of ``case`` (cached). A fault case on the nominal geometry is the nominal
    recording with the fault applied: what :func:`simulate_skin` gives, without simulating the
    same skin twice."""
    path = out / "data" / f"{case.name}.h5"
    if path.exists():
        return read_recording(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if case.role == "fault" and nominal is not None:
        log.info("skin %s: the nominal recording with the fault at the readout", case.name)
        meta = {**nominal.meta, "fabrication": case.skin.to_dict()}
        rec = apply_fault(
            replace(nominal, meta=meta), case.skin.fault, config.protocol.readout, case.skin.seed
        )
    else:
        log.info("simulating skin %s (%s, scale %.2f)", case.name, case.role, case.scale)
        rec = simulate_skin(
            config.protocol, case.skin, workers=config.workers, progress=config.progress
        )
    write_recording(rec, path)
    return read_recording(path)


def _rest_reference(rec: Recording) -> np.ndarray:
    """(n_pairs,) the mean rest-state readout of ``rec`` (pF)."""
    return next(iter(touch_reference(rec, reference="rest").values()))


def own_rest_reference(rec: Recording, nominal: np.ndarray) -> np.ndarray:
    """(n_pairs,) ``rec``'s own mean rest readout (pF), refused when a channel reads less
    than :data:`DEAD_FRACTION` of its nominal rest readout: a dead channel (its mean is noise
    around 0, and Eq. 2 would divide the frames by that noise)."""
    own = _rest_reference(rec)
    dead = np.flatnonzero(np.abs(own) < DEAD_FRACTION * np.abs(nominal))
    if dead.size:
        names = [rec.layout.pair_names[j] for j in dead]
        raise EctskinError(
            f"channels {names} read less than {DEAD_FRACTION:.0%} of their nominal rest "
            "readout (dead); Eq. 2 cannot divide by them"
        )
    return own


def _profile(task: str, config: VariabilityConfig) -> str:
    return config.touch_profile if task == "touch" else config.profile


def _train_config(task: str, config: VariabilityConfig) -> TrainConfig:
    # every skin is scored on frames calibrated against one rest readout: train on such frames
    return TrainConfig(
        reference="rest" if task == "touch" else None,
        profile=_profile(task, config),
        seed=config.seed,
        progress=config.progress,
        threads=config.threads,
        resume=True,
        epochs=config.epochs,
    )


def _train_nominal(out: Path, task: str, config: VariabilityConfig) -> Path:
    run = out / "runs" / f"{task}_nominal"
    done = run / "variability_done.json"
    if not done.exists():
        log.info("training %s on the nominal skin", task)
        summary = train_from_recording(
            task, out / "data" / "nominal.h5", run, _train_config(task, config)
        )
        write_json_atomic(done, summary)
    return run


def _train_dr(
    out: Path,
    task: str,
    recs: list[Recording],
    reference: np.ndarray,
    split: dict[str, Any],
    config: VariabilityConfig,
) -> Path:
    """The domain-randomised model: the train and val trials of the nominal split of every skin
    in ``recs``, each calibrated against ``reference`` (the nominal rest readout)."""
    run = out / "runs" / f"{task}_dr"
    done = run / "variability_done.json"
    if done.exists():
        return run
    t = get_task(task)
    parts: dict[str, list[SampleData]] = {"train": [], "val": []}
    for rec in recs:
        ds = t.dataset(rec, reference=reference, **_dataset_options(task))
        for k in parts:
            parts[k].append(_trials(ds, split[k], rec))
    joined = {k: type(v[0]).concat(v) for k, v in parts.items()}
    names = {k: [f"{i}/{n}" for i in range(len(recs)) for n in split[k]] for k in parts}
    log.info("training %s on %d skins (domain randomisation)", task, len(recs))
    summary = train(
        task,
        joined["train"],
        joined["val"],
        run,
        _train_config(task, config),
        split={**names, "test": [], "task": task, "data": "domain randomisation"},
    )
    write_json_atomic(done, summary)
    return run


def _dataset_options(task: str) -> dict[str, Any]:
    """The data-set options of :func:`_train_config`'s runs (contact: a window of 10 frames)."""
    return {"window": TrainConfig().window} if task == "contact" else {}


def _trials(ds: SampleData, names: list[str], rec: Recording) -> SampleData:
    """The samples of the trials ``names`` of ``ds`` (built from ``rec``)."""
    source = f"recording {rec.source or ''} (every skin must run the nominal protocol)"
    return ds.select(ds.group_ids(names, source=source))


# ----------------------------------------------------------------------------- evaluation
def _evaluated(
    out: Path,
    case: SkinCase,
    rec: Recording,
    nom_ref: np.ndarray,
    runs: dict[tuple[str, str], Path],
    config: VariabilityConfig,
) -> dict[str, Any]:
    path = out / "eval" / f"{case.name}.json"
    if path.exists():
        return read_json_object(path, "evaluation")
    log.info("evaluating on skin %s", case.name)
    own, own_error = None, None
    try:
        own = own_rest_reference(rec, nom_ref)
    except EctskinError as exc:
        own_error = str(exc)
    res: dict[str, Any] = {
        "role": case.role,
        "scale": case.scale,
        "fabrication": case.skin.to_dict(),
        "rest_deviation_pct": None
        if own is None
        else float(100 * np.sqrt(np.mean(((own - nom_ref) / nom_ref) ** 2))),
    }
    refs = {"nominal": nom_ref, "own": own}
    with torch_threads(config.threads):
        for task, metric in TASKS.items():
            scores: dict[str, Any] = {}
            nominal_run = read_run(runs[(task, "nominal")])
            test_names = nominal_run.split["test"]
            for name, which, ref in EVALUATIONS:
                model, model_config, _ = load_checkpoint(runs[(task, which)] / "model.pt")
                if refs[ref] is None:
                    scores[name] = None
                    scores[f"{name}_note"] = f"no own rest reference: {own_error}"
                    continue
                scores[name] = score(task, model, model_config, rec, refs[ref], test_names)
            scores["finetune"] = {
                str(n): _finetuned_score(task, nominal_run, rec, nom_ref, n, case, config)
                for n in config.finetune_frames
            }
            res[task] = {"metric": metric, **scores}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, res)
    return res


def score(
    task: str,
    model: torch.nn.Module,
    model_config: Any,
    rec: Recording,
    reference: np.ndarray,
    names: list[str],
) -> float | None:
    """The task's metric (:data:`TASKS`) of ``model`` on the trials ``names`` of ``rec``, every
    frame calibrated against ``reference`` (n_pairs,) pF."""
    t = get_task(task)
    ds = t.dataset(rec, reference=reference, **t.dataset_options(model_config))
    test = _trials(ds, names, rec)
    pred = t.predict(model, test)
    m = t.test_metrics(EvalCase(data=ds, test=test, pred=pred, recording=rec, config=model_config))
    v = m[TASKS[task]]
    return None if v is None else float(v)


def _finetuned_score(
    task: str,
    run: Run,
    rec: Recording,
    reference: np.ndarray,
    n: int,
    case: SkinCase,
    config: VariabilityConfig,
) -> float | None:
    names = run.split["test"]
    if n == 0:
        return score(task, run.model, run.config, rec, reference, names)
    t = get_task(task)
    ds = t.dataset(rec, reference=reference, **t.dataset_options(run.config))
    pool = _trials(ds, run.split["train"], rec)
    rng = np.random.default_rng([config.seed, 17, n, sum(map(ord, case.name))])
    take = rng.choice(pool.n_samples, size=min(n, pool.n_samples), replace=False)
    sample = pool.take(np.sort(take))
    model, _ = finetune_run(task, run.path, sample, sample, finetune_config(task, config))
    return score(task, model, run.config, rec, reference, names)


def finetune_config(task: str, config: VariabilityConfig) -> TrainConfig:
    """The :class:`TrainConfig` of the study's fine-tunes (recovery c): the task's profile with
    ``finetune_epochs`` epochs of Adam at a constant ``finetune_lr`` (``step_size`` = the epochs)
    in batches of :data:`FINETUNE_BATCH`, every sample once per epoch, no augmentation (none of
    the profile's), the epoch of the lowest validation loss kept."""
    epochs = config.finetune_epochs
    return TrainConfig(
        profile=_profile(task, config),
        seed=config.seed,
        epochs=epochs,
        batch_size=FINETUNE_BATCH,
        settings={
            "lr": config.finetune_lr,
            "step_size": max(epochs, 1),
            "samples_per_epoch": None,
            "val_samples": None,
            "inflation_shift": False,
            "channel_gain": 0.0,
            "mixup_alpha": 0.0,
            "label_smoothing": 0.0,
            "select": "val_loss",
        },
        threads=config.threads,
        progress=False,
        resume=False,
    )


def finetune_run(
    task: str,
    init_from: str | Path,
    train_data: SampleData,
    val_data: SampleData,
    config: TrainConfig,
    out: str | Path | None = None,
) -> tuple[torch.nn.Module, dict[str, Any]]:
    """Fine-tune the trained run ``init_from`` (a run folder or its ``model.pt``) on in-memory
    data: :func:`~ectskin.learn.train.train` with ``config.init_from`` set, the path of
    ``ectskin train TASK NEW.h5 --init-from RUN`` (:mod:`ectskin.learn.finetune`: the base run's
    config, normaliser and weights; the base scored on ``val_data`` and kept as epoch 0 unless
    an epoch beats it there). The run folder is ``out``, or a temporary one removed afterwards.
    Returns the kept model (``model.pt``, in eval mode) and train's summary."""
    cfg = replace(config, init_from=str(init_from), resume=False)
    with contextlib.ExitStack() as stack:
        folder = (
            Path(out)
            if out is not None
            else Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="ectskin-ft-")))
        )
        summary = train(task, train_data, val_data, folder, cfg)
        model, _, _ = load_checkpoint(folder / "model.pt", kind=get_task(task).model_kind)
    return model.eval(), summary


# ----------------------------------------------------------------------------- summary, report
def summarise(results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Mean of each evaluation over the sampled skins, per task, and the nominal skin's values."""
    out: dict[str, Any] = {}
    sampled = [r for r in results.values() if r["role"] == "sampled"]
    for task in TASKS:
        rows = {}
        for name in [e[0] for e in EVALUATIONS] + ["finetune"]:
            if name == "finetune":
                keys = sampled[0][task]["finetune"].keys() if sampled else []
                for k in keys:
                    rows[f"finetune_{k}"] = _mean([r[task]["finetune"][k] for r in sampled])
            else:
                rows[name] = _mean([r[task][name] for r in sampled])
        out[task] = {"sampled_mean": rows}
        if "nominal" in results:
            out[task]["nominal_baseline"] = results["nominal"][task]["baseline"]
    return out


def _mean(values: list[Any]) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else None


def _config_dict(config: VariabilityConfig) -> dict[str, Any]:
    d = asdict(replace(config, layout=None, protocol=DEFAULT_PROTOCOL))
    d["protocol"] = config.protocol.to_dict()
    d["layout"] = (config.layout or default_layout()).name
    return d


def _figures(out: Path, results: dict[str, Any], config: VariabilityConfig) -> dict[str, str]:
    figs = {
        "variability_curves.png": (plot_degradation(results), "metric against perturbation scale"),
        "variability_finetune.png": (plot_finetune(results), "metric against fine-tuning frames N"),
    }
    for name, (fig, _) in figs.items():
        save_figure_atomic(fig, out / name)
    return {name: caption for name, (_, caption) in figs.items()}


def _fmt(v: Any, task: str) -> str:
    if v is None:
        return "–"
    return f"{v:.3f}" if task == "touch" else f"{v:.1f}"


def report_markdown(doc: dict[str, Any]) -> str:
    """The study as Markdown: one table per task (a row per skin, a column per evaluation)."""
    cfg = doc["config"]
    lines = [
        "# Fabrication variability",
        "",
        f"Skins: {len(doc['skins'])} scored (nominal, sampled at scales "
        f"{cfg['scale_range'][0]:g}–{cfg['scale_range'][1]:g} × the assumed spreads, faults); "
        f"domain randomisation on {cfg['dr_skins']} more skins; profiles: touch "
        f"{cfg['touch_profile']}, contact {cfg['profile']}; "
        f"seed {cfg['seed']}; {doc['seconds'] / 60:.1f} min.",
        "Spreads (assumed): " + ", ".join(f"{k} {v}" for k, v in cfg["variation"].items()) + ".",
        "",
    ]
    ft_keys = None
    for task, metric in TASKS.items():
        first = next(iter(doc["skins"].values()))[task]
        ft_keys = list(first["finetune"].keys())
        head = ["skin", "scale", "rest dev. %"] + [e[0] for e in EVALUATIONS]
        head += [f"finetune N={k}" for k in ft_keys if k != "0"]
        rows = []
        for name, r in doc["skins"].items():
            dev = r["rest_deviation_pct"]
            row = [name, f"{r['scale']:g}", "–" if dev is None else f"{dev:.1f}"]
            row += [_fmt(r[task][e[0]], task) for e in EVALUATIONS]
            row += [_fmt(r[task]["finetune"][k], task) for k in ft_keys if k != "0"]
            rows.append(row)
        lines += [f"## {task}: {metric}", ""] + markdown_table(head, rows)
        mean = doc["summary"][task]["sampled_mean"]
        lines += [
            "",
            "Mean over the sampled skins: "
            + ", ".join(f"{k} {_fmt(v, task)}" for k, v in mean.items())
            + ".",
            "",
        ]
    lines += ["## Figures", ""] + [f"* `{k}`: {v}" for k, v in doc.get("figures", {}).items()]
    lines += [
        "",
        "The fault rows use the nominal geometry. A dead electrode, and a short (its own pair), "
        "have no own rest reference: those channels read ~0 at rest.",
        "",
    ]
    return "\n".join(lines)
