"""Named training profiles: the optimisation settings and the touch recipe of each task, and
:class:`TrainConfig`, how a run trains.

:data:`PROFILES` maps profile → task → :class:`TrainSettings`; :func:`profile_settings` picks
one and applies overrides, checking every field at the door. :class:`TrainConfig` names the
profile, its overrides and the run's other options (seed, device, data-set options, model
choice); it is what :func:`ectskin.learn.train.train` and ``train_from_recording`` take.

* ``paper``: the paper's settings (§4): Adam, lr 1e-3 divided by 1.2 every 15 epochs (StepLR,
  gamma 1/1.2); touch 100 epochs of batch 256, track 150 epochs of batch 255; the weights with
  the lowest validation loss are kept.
* ``quick``: for a laptop CPU. Touch 30 epochs of batch 256, the learning rate divided by 1.2
  every 5 epochs. Track 20 epochs, each on a fresh random subset of 8 192 training windows
  (windows of one trajectory are strongly correlated, so a subset per epoch loses little),
  batch 256, divided by 1.2 every 2 epochs, validated on a fixed subset of 4 096 windows. Both
  keep the paper's optimizer and best-validation rule.
* contact (ours, :mod:`ectskin.learn.tasks.contact`): ``paper`` = the paper's optimiser for
  100 epochs of batch 256; ``quick`` = 15 epochs, each on a fresh random subset of 32 768
  training windows, validated on a fixed subset of 16 384, the learning rate divided by 1.2
  every 3 epochs. Both add the inflation shift of the ``robust`` recipe to every training
  window and keep the weights with the lowest validation localisation error.
* ``robust`` (touch only; ours, not the paper's): the paper's TouchMLP, unchanged, trained with
  a recipe meant to generalise to unseen (inflation state, touch placement) combinations. Its
  frames are the touch's change of the readout from the rest readout of their own inflation
  state, in units of the rest state's readout (reference ``"state-offset"``: c = (c_t −
  c_0(p)) / c_0(0), c_0(p) the mean of the state's no-contact trial(s), c_0(0) that of the
  uninflated state, :mod:`ectskin.io.inflation_reference`; :data:`PROFILE_REFERENCE`,
  ``TrainConfig.reference`` overrides it). Subtracting c_0(p) removes what the inflation does
  to the untouched readout; dividing by c_0(p) instead, as reference ``"state"`` does, would
  also rescale each channel by c_0(0) / c_0(p) with the inflation, while the touch's change
  c_t − c_0(p) follows c_0(p) only in part (chosen by validation accuracy, see
  ``BENCHMARKS.md``). Per training frame it adds
  an *inflation shift*, the difference between the mean no-contact frames of two training
  inflation states drawn at random ("the same touch seen at another inflation", see
  :mod:`ectskin.learn.augment`; about zero once each state's rest is subtracted, it matters
  with the rest reference), scales each of its values by a gain of its own, exp(N(0, 0.1²))
  (a *gain per channel*: how much a touch changes each pair's readout varies with the state
  and the finger by some ten per cent that the reference does not remove), then mixes each
  frame with a frame of the *same class* (mixup within each class, Beta(1, 1), a λ per
  sample: a touch of the same region between two training trials), uses
  cross-entropy with label smoothing 0.1, Adam 1e-3 divided by 1.2 every
  5 epochs, batch 256, 20 epochs, and keeps the weights with the best validation *accuracy*,
  ties broken by the lower validation loss.

Measured training times are in ``BENCHMARKS.md``; a run's accuracy is in its ``metrics.json``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option

#: Rules that pick the kept weights: lowest validation loss, or best validation metric.
SELECT = ("val_loss", "val_metric")


@dataclass(frozen=True)
class TrainSettings:
    """Optimisation settings of one profile and task (Adam + StepLR, paper §4), and the touch
    recipe: augmentation, label smoothing and the rule that picks the kept weights (defaults:
    the paper's; the ``robust`` profile sets them)."""

    epochs: int
    batch_size: int  # global batch (split over DDP ranks)
    lr: float = 1e-3
    step_size: int = 15  # StepLR: epochs between learning-rate decays
    gamma: float = 1 / 1.2  # "decayed by a factor of 1.2 every 15 epochs"
    samples_per_epoch: int | None = None  # None: every training sample once per epoch
    val_samples: int | None = None  # None: the whole validation set each epoch
    eval_batch_size: int = 2048
    # --- touch recipe (defaults: the paper's, no augmentation) --------------------------------
    inflation_shift: bool = False  # add mean(no-contact state a) - mean(state b) per frame
    mixup_alpha: float = 0.0  # > 0: mixup with Beta(alpha, alpha), one lambda per sample
    mixup_pairs: str = "any"  # mixup partners: any frame of the batch, or one of the same class
    label_smoothing: float = 0.0  # of the training cross-entropy (validation loss: plain CE)
    select: str = "val_loss"  # keep the weights of the lowest val_loss or the best val_metric
    channel_gain: float = 0.0  # > 0: each value scaled by exp(N(0, channel_gain)), per channel
    # --- contact: a training window takes another training finger's signal with this
    # probability (ectskin.learn.tasks.contact_mix; off in every profile, measured in
    # BENCHMARKS.md: two fingers counted right, one finger a little less often)
    finger_mix: float = 0.0

    @property
    def augments(self) -> bool:
        return self.inflation_shift or self.mixup_alpha > 0 or self.channel_gain > 0


#: profile → task → settings (see the module docstring).
PROFILES: dict[str, dict[str, TrainSettings]] = {
    "paper": {
        "touch": TrainSettings(epochs=100, batch_size=256),
        "track": TrainSettings(epochs=150, batch_size=255),
        "contact": TrainSettings(
            epochs=100, batch_size=256, inflation_shift=True, select="val_metric"
        ),
    },
    "quick": {
        "touch": TrainSettings(epochs=30, batch_size=256, step_size=5),
        "track": TrainSettings(
            epochs=20, batch_size=256, step_size=2, samples_per_epoch=8192, val_samples=4096
        ),
        "contact": TrainSettings(
            epochs=15,
            batch_size=256,
            step_size=3,
            samples_per_epoch=32768,
            val_samples=16384,
            inflation_shift=True,
            select="val_metric",
        ),
    },
    "robust": {
        "touch": TrainSettings(
            epochs=20,
            batch_size=256,
            step_size=5,
            inflation_shift=True,
            mixup_alpha=1.0,
            mixup_pairs="class",
            label_smoothing=0.1,
            select="val_metric",
            channel_gain=0.1,
        ),
    },
}
#: The tasks that have training settings, in the order of :data:`PROFILES`.
PROFILE_TASKS = tuple(dict.fromkeys(task for per_task in PROFILES.values() for task in per_task))
#: Tasks that learn class labels: the recipe's augmentation and label smoothing apply to them.
RECIPE_TASKS = ("touch",)
#: Tasks whose training may add the inflation shift (touch, and contact, which reads the same
#: calibrated frames)
SHIFT_TASKS = ("touch", "contact")
#: The fields of the touch recipe, stored as ``recipe`` in config.json and metrics.json.
RECIPE_FIELDS = (
    "inflation_shift",
    "mixup_alpha",
    "mixup_pairs",
    "label_smoothing",
    "select",
    "channel_gain",
)
#: ``TrainSettings.mixup_pairs``: partners among all frames of the batch, or of the same class
MIXUP_PAIRS = ("any", "class")
#: profile → the Eq. 2 reference its touch data is calibrated with
#: (:func:`ectskin.io.calibration.touch_reference`) unless ``TrainConfig.reference`` says
#: otherwise: "auto" (the rest state, the paper's) or one that follows the inflation
PROFILE_REFERENCE = {"paper": "auto", "quick": "auto", "robust": "state-offset"}
#: Tasks whose data set takes a ``reference`` other than "auto" from :class:`TrainConfig`
REFERENCE_TASKS = ("touch",)
#: ``TrainConfig.reference`` values: ectskin.io.calibration.REFERENCE_OPTIONS, listed here because
#: importing ``ectskin.io`` loads h5py, which the command-line parser (it imports this module)
#: would pay for (a test keeps the two equal)
REFERENCES = ("auto", "rest", "meta", "state", "inflation", "state-offset", "inflation-offset")


def profiles_for(task: str) -> tuple[str, ...]:
    """The names of the profiles that have settings for ``task``."""
    return tuple(name for name, per_task in PROFILES.items() if task in per_task)


def profile_settings(task: str, profile: str = "paper", **overrides: Any) -> TrainSettings:
    """The :class:`TrainSettings` of ``profile`` for ``task`` with ``overrides`` applied
    (e.g. ``samples_per_epoch=None`` to use every training sample in the quick profile)."""
    check_option("task", task, PROFILE_TASKS)
    check_option("profile", profile, tuple(PROFILES))
    if task not in PROFILES[profile]:
        available = ", ".join(repr(p) for p in profiles_for(task))
        raise EctskinError(
            f"profile {profile!r} has no settings for task {task!r} (it exists for "
            f"{', '.join(repr(t) for t in PROFILES[profile])} only); profiles for {task!r}: "
            f"{available}"
        )
    names = {f.name for f in fields(TrainSettings)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise EctskinError(f"unknown training setting(s): {', '.join(unknown)}")
    settings = replace(PROFILES[profile][task], **overrides)
    _check_settings(settings)
    shift = settings.inflation_shift and task not in SHIFT_TASKS
    others = settings.mixup_alpha > 0 or settings.label_smoothing > 0 or settings.channel_gain > 0
    if settings.finger_mix and task != "contact":
        raise EctskinError(
            f"training setting 'finger_mix' applies to task 'contact' only, got "
            f"{settings.finger_mix!r} for {task!r}"
        )
    if task not in RECIPE_TASKS and (shift or others):
        raise EctskinError(
            "training settings 'inflation_shift', 'mixup_alpha', 'label_smoothing' and "
            f"'channel_gain' apply to task {' or '.join(repr(t) for t in RECIPE_TASKS)} only, "
            f"got {settings.inflation_shift!r}, {settings.mixup_alpha!r}, "
            f"{settings.label_smoothing!r}, {settings.channel_gain!r} for {task!r}"
        )
    return settings


@dataclass(frozen=True)
class TrainConfig:
    """How :func:`~ectskin.learn.train.train` and
    :func:`~ectskin.learn.train.train_from_recording` train.

    profile : "paper", "quick" or (touch only) "robust" (:data:`PROFILES`); ``epochs``,
        ``batch_size`` and ``settings`` (any :class:`TrainSettings` field) override it. The
        default, "paper", is meant for a GPU: on a CPU training warns so at the start and logs
        the time left after its first epoch.
    seed : seeds the trial split (unless ``split_seed``), model initialisation, epoch
        permutations, dropout and augmentation.
    window, prior : the data set (frames per window; prior knowledge); read by
        ``train_from_recording`` only (``train`` takes the data sets built).
    resume : continue the run in the output folder (same settings and data required); False
        starts over.
    device : "cpu", "cuda", "cuda:1"...; default CUDA when available (per rank under torchrun).
    progress : progress bars on a terminal, one log line per epoch otherwise.
    counts : trials per split (train, val, test), scaled to the data; default the task's
        (the paper's 125/32/32 touch, 108/18/20 tracking trials); ``train_from_recording`` only.
    split_seed : the seed of the trial split (default ``seed``); ``train_from_recording`` only.
    model_options : model hyper-parameters (e.g. ``{"d_model": 32}``); the shape fields come
        from the data.
    threads : torch CPU threads while training (:mod:`ectskin.learn.threads`: an int, "auto");
        None: :data:`~ectskin.learn.threads.TRAIN_DEFAULT_THREADS`. Ignored on CUDA. The
        classical candidates use as many native threads.
    model : touch: "mlp" (the paper's TouchMLP, default), "auto" (every candidate, the
        best on validation selected) or one classical candidate
        (:data:`~ectskin.learn.candidates.TOUCH_MODELS`, see :mod:`ectskin.learn.touch_choice`);
        contact: "contactnet" ("mlp" means it too), "auto", "knn", "ridge", "gbt" or "gp"
        (:mod:`ectskin.learn.contact_choice`).
    settings : overrides of any :class:`TrainSettings` field (e.g. ``{"step_size": 2}``).
    init_from : a trained run (or its ``model.pt``) to fine-tune: its config, normaliser and
        weights are the start (:mod:`ectskin.learn.finetune`); ``epochs`` may then be 0 (the
        base weights kept as they are).
    reference : touch: the Eq. 2 reference of the data set
        (:func:`ectskin.io.calibration.touch_reference`: "auto", "rest", "meta", "state",
        "inflation"); None: the profile's (:data:`PROFILE_REFERENCE`). Read by
        ``train_from_recording`` only; the run stores it and evaluation re-applies it.
    extra_train : recordings whose trials join the training split only, each calibrated against
        its own rest readouts with the run's reference (:mod:`ectskin.learn.extra_train`; e.g. the
        twin's coverage trials, :mod:`ectskin.twin.coverage`); ``train_from_recording`` only.
    """

    profile: str = "paper"
    seed: int = 0
    epochs: int | None = None
    batch_size: int | None = None
    window: int = 10
    prior: bool = True
    resume: bool = True
    device: str | None = None
    progress: bool = True
    counts: tuple[float, float, float] | None = None
    split_seed: int | None = None
    model_options: dict[str, Any] | None = None
    threads: int | str | None = None
    model: str = "mlp"
    settings: dict[str, Any] | None = None
    init_from: str | None = None
    reference: str | None = None
    extra_train: tuple[str, ...] = ()

    def reference_for(self, task: str) -> str:
        """The Eq. 2 reference of ``task``'s data set: :attr:`reference`, else the profile's
        (:data:`PROFILE_REFERENCE`); "auto" for a task other than touch (where another value is
        an error)."""
        if self.reference is not None:
            check_option("reference", self.reference, REFERENCES, source="TrainConfig")
        if task not in REFERENCE_TASKS:
            if self.reference not in (None, "auto"):
                raise EctskinError(
                    f"TrainConfig: reference {self.reference!r} applies to task "
                    f"{' or '.join(repr(t) for t in REFERENCE_TASKS)} only, got task {task!r}"
                )
            return "auto"
        if self.reference is not None:
            return self.reference
        return PROFILE_REFERENCE.get(self.profile, "auto")

    def settings_for(self, task: str) -> TrainSettings:
        """The :class:`TrainSettings` of :attr:`profile` for ``task`` with :attr:`settings`,
        :attr:`epochs` and :attr:`batch_size` applied (checked: :func:`profile_settings`)."""
        overrides = dict(self.settings or {})
        for name in ("epochs", "batch_size"):
            if getattr(self, name) is not None:
                overrides[name] = getattr(self, name)
        if self.init_from is not None and overrides.get("epochs") == 0:
            # a fine-tune of 0 epochs keeps the base run's weights (ectskin.learn.finetune)
            overrides["epochs"] = 1
            return replace(profile_settings(task, self.profile, **overrides), epochs=0)
        return profile_settings(task, self.profile, **overrides)


def _check_settings(settings: TrainSettings) -> None:
    """Every field of ``settings`` in its range, or an EctskinError naming the field."""
    for name in ("epochs", "batch_size", "step_size", "eval_batch_size"):
        v = getattr(settings, name)
        if not isinstance(v, int | np.integer) or isinstance(v, bool) or v < 1:
            raise EctskinError(f"training setting {name!r} must be a positive integer, got {v!r}")
    for name in ("samples_per_epoch", "val_samples"):
        v = getattr(settings, name)
        if v is not None and (not isinstance(v, int | np.integer) or v < 1):
            raise EctskinError(f"training setting {name!r} must be None or >= 1, got {v!r}")
    if not (settings.lr > 0 and math.isfinite(settings.lr)):
        raise EctskinError(f"training setting 'lr' must be > 0, got {settings.lr!r}")
    if not 0 < settings.gamma <= 1:
        raise EctskinError(f"training setting 'gamma' must be in (0, 1], got {settings.gamma!r}")
    if not isinstance(settings.inflation_shift, bool | np.bool_):
        raise EctskinError(
            f"training setting 'inflation_shift' must be True or False, got "
            f"{settings.inflation_shift!r}"
        )
    if not (settings.mixup_alpha >= 0 and math.isfinite(settings.mixup_alpha)):
        raise EctskinError(
            f"training setting 'mixup_alpha' must be >= 0 (0: no mixup), got "
            f"{settings.mixup_alpha!r}"
        )
    if not (isinstance(settings.finger_mix, int | float) and 0 <= settings.finger_mix <= 1):
        raise EctskinError(
            f"training setting 'finger_mix' must be a probability from 0 to 1, got "
            f"{settings.finger_mix!r}"
        )
    if not 0 <= settings.label_smoothing < 1:
        raise EctskinError(
            f"training setting 'label_smoothing' must be in [0, 1), got "
            f"{settings.label_smoothing!r}"
        )
    if not (settings.channel_gain >= 0 and math.isfinite(settings.channel_gain)):
        raise EctskinError(
            f"training setting 'channel_gain' must be >= 0 (0: no gain), got "
            f"{settings.channel_gain!r}"
        )
    check_option("select", settings.select, SELECT)
    check_option("mixup_pairs", settings.mixup_pairs, MIXUP_PAIRS)


def describe_recipe(recipe: Mapping[str, Any] | None, metric: str = "accuracy") -> str:
    """A phrase for a run's training recipe (``recipe`` of its config.json), e.g. "inflation
    shift over 25 no-contact training states, mixup (Beta 0.4, 0.4), label smoothing 0.1, weights
    of the best validation accuracy"; "the paper's recipe" for none of these."""
    if not recipe:
        return "the paper's recipe"
    parts = []
    reference = recipe.get("reference")
    if reference in ("state", "state-offset"):
        parts.append("frames calibrated against the rest readout of their own inflation state")
    elif reference in ("inflation", "inflation-offset"):
        parts.append("frames calibrated against the rest readout predicted at their inflation")
    if reference in ("state-offset", "inflation-offset"):
        parts[-1] += " (divided by the 0-ml rest readout)"
    if recipe.get("inflation_shift"):
        n = int(recipe.get("inflation_shift_states") or 0)
        parts.append(
            f"inflation shift over {n} no-contact training states"
            if n >= 2
            else "inflation shift skipped (fewer than 2 no-contact training trials)"
        )
    alpha = float(recipe.get("mixup_alpha") or 0)
    if alpha > 0:
        within = " within each class" if recipe.get("mixup_pairs") == "class" else ""
        parts.append(f"mixup{within} (Beta {alpha:g}, {alpha:g})")
    gain = float(recipe.get("channel_gain") or 0)
    if gain > 0:
        parts.append(f"a gain per channel (log-normal, sigma {gain:g})")
    smoothing = float(recipe.get("label_smoothing") or 0)
    if smoothing > 0:
        parts.append(f"label smoothing {smoothing:g}")
    for extra in recipe.get("extra_train") or []:
        parts.append(f"{int(extra['trials'])} extra training trials of {extra['file']}")
    if recipe.get("select") == "val_metric":
        parts.append(f"weights of the best validation {metric}")
    elif parts:
        parts.append("weights of the lowest validation loss")
    return ", ".join(parts) or "the paper's recipe"
