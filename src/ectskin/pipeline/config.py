"""What a reproduction runs: the trainings of the paper's runs and :class:`ReproduceConfig`.

The runs (``OUT_DIR/runs/<name>``), each a training of :mod:`ectskin.learn.train` on the same
data and split seed:

==================  =======  ======  =====  ==========================================
run                 task     window  prior  role
==================  =======  ======  =====  ==========================================
``touch``           touch    10      yes    the paper's TouchMLP
``touch_robust``    touch    10      yes    the same network, ``robust`` profile (ours)
``track``           track    10      yes    the paper's C2DT
``track_no_prior``  track    10      no     ablation: absolute calibration, no initial coordinates
``track_window_1``  track    1       yes    ablation: 1 frame instead of 10
``contact``         contact  10      –      ours: finger count, points, forces, hover, on
                                            the contact experiment (``contact.h5``)
==================  =======  ======  =====  ==========================================

The contact run trains on ``contact.h5``: the paper's trials of ``data.h5`` together with the
*contact experiment* (:meth:`ReproduceConfig.contact_protocol`): the paper's finger, forces and
handling, with the chambers at their lowest and highest level (8 states), dense touches read
from the states' response fields (:mod:`ectskin.pipeline.field`): in each trial the finger
presses at a new point anywhere in its region every :data:`CONTACT_DWELL_S`, sliding in contact to
it, lifting, hovering and approaching, with a second finger in some trials: what
continuous contact models need and the paper's protocol does not hold.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ectskin._check import EctskinError, check_option, check_type
from ectskin.io import Recording
from ectskin.layout import default_layout
from ectskin.learn.candidates import TOUCH_MODELS
from ectskin.learn.threads import resolve_threads
from ectskin.twin import Protocol
from ectskin.twin.coverage import coverage_protocol
from ectskin.twin.field_spec import FIELD_GRIDS
from ectskin.viz import DEFAULT_DPI, check_figure_options

#: Training profiles of a reproduction (:data:`ectskin.learn.train.PROFILES` apply per run).
PROFILES = ("quick", "paper")

#: run name → (task, window, prior).
RUNS: dict[str, tuple[str, int, bool]] = {
    "touch": ("touch", 10, True),
    "touch_robust": ("touch", 10, True),
    "track": ("track", 10, True),
    "track_no_prior": ("track", 10, False),
    "track_window_1": ("track", 1, True),
    "contact": ("contact", 10, True),
}
#: the run trained on the contact experiment
CONTACT_RUN = "contact"
#: ablation key in metrics.json → run name
ABLATIONS = {"no_prior": "track_no_prior", "window_1": "track_window_1"}
#: runs trained with a fixed profile of ectskin.learn.train instead of the config's ``profile``
RUN_PROFILES = {"touch_robust": "robust"}
#: epochs of the ablation trainings under the quick profile (the main runs use the profile's)
QUICK_ABLATION_EPOCHS = 12
#: the states whose fields the bound and the inversion read (ReproduceConfig.field_states)
FIELD_STATES = ("contact", "all")
#: where the bound's push columns come from (ReproduceConfig.bound_push_columns; the same as
#: ectskin.twin.bound_field.PUSH_COLUMNS, which tests/pipeline/test_bound_push_option.py checks)
BOUND_PUSH_COLUMNS = ("untouched", "finger")
#: the inversion's person's finger (ReproduceConfig.inversion_finger; the inversion step's
#: ``finger``, ectskin.pipeline.inversion.FINGER_CHOICES)
INVERSION_FINGER = ("auto", "on", "off")
#: how the contact experiment's touch trials are read (ReproduceConfig.contact_response)
CONTACT_RESPONSES = ("field", "solve")
#: the contact experiment read from the fields (ReproduceConfig.contact_protocol): touch trials
#: per state, seconds per point (dwell: 60 points in a 30-s trial), the part of each dwell spent
#: sliding to the next point, and its own random streams (Protocol.stream: its trials share no
#: draw with the paper's)
CONTACT_TOUCH_TRIALS = 9
CONTACT_DWELL_S = 0.5
CONTACT_SLIDE = 1 / 3
CONTACT_STREAM = 1


def _check_positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise EctskinError(f"{name} must be an integer >= 1, got {value!r}")
    return value


@dataclass(frozen=True)
class ReproduceConfig:
    """Settings of :func:`ectskin.pipeline.reproduce`; checked when made.

    Parameters
    ----------
    out_dir : path
        Output folder (created). Finished steps found there are reused
        (:mod:`ectskin.pipeline.runner`).
    profile : "quick" | "paper"
        Training settings of the paper's runs and the ablations (:data:`PROFILES`).
    seed : int
        Seeds the simulation protocol (when ``protocol`` is None), the splits and the training.
    workers : int, optional
        Cores to use (default: all): simulation processes, and the training runs side by side
        (``workers`` // torch threads of them; :func:`ectskin.pipeline.steps.training_processes`).
    force : bool
        Redo steps whose earlier results in ``out_dir`` were made with other settings (the
        command line's ``--overwrite``).
    protocol : ectskin.twin.Protocol, optional
        The experiment to simulate (default: the paper's, ``Protocol(seed=seed)``).
    recording : Recording, optional
        Use this recording instead of simulating one (written to ``out_dir/data.h5``); excludes
        ``protocol``, and the twin's characterisation is skipped.
    epochs : int or {run name: int}, optional
        Override the profile's epochs (run names: :data:`RUNS`; a "touch" entry also applies to
        "touch_robust", a "track" entry to the ablations).
    ablations, baselines, characterize : bool
        Include the two tracking ablations, the baselines, the twin's characterisation.
    robust : bool
        Also train and evaluate the TouchMLP with the ``robust`` profile.
    coverage : bool
        The ``robust`` run also trains on the twin's coverage trials (every touch region in
        every inflation state of the simulated protocol, :mod:`ectskin.twin.coverage`; training
        split only); ignored with a given recording.
    touch_model : str
        The model of the ``touch`` run: ``mlp`` (the paper's TouchMLP) or a choice of
        :mod:`ectskin.learn.candidates` (``auto``: every candidate, selected on the validation
        split; the report lists them all).
    contact : bool
        Also simulate the contact experiment (:meth:`contact_protocol`; with a given
        ``recording``: that recording, when it carries finger ground truth), train and evaluate
        the contact model on it with its baselines, and reconstruct ECT images of its test
        touches.
    device : str, optional
        Training device (default: CUDA when available).
    progress : bool
        Progress bars.
    threads : int, "auto" or None
        Torch CPU threads of training and evaluation (:mod:`ectskin.learn.threads`; None:
        torch's current setting).
    command : str, optional
        The command line that made the run, written into metrics.json and the report so that
        every figure there says how to get it again (the CLI passes its own).
    figure_format, dpi : str, int
        File format (``png``, ``pdf``, ``svg``) and resolution of the evaluations' figures
        (:func:`ectskin.viz.check_figure_options`).
    contact_response : "field" | "solve"
        How the contact experiment's touch trials are read: from the states' response fields
        (dense: a point every :data:`CONTACT_DWELL_S`; the fields are built once into
        ``field_cache``), or by method-of-moments solves per point (4 touch trials per state of
        2 points each, no field to build).
    field_cache : path, optional
        Where the contact experiment's response fields are cached (default:
        :func:`ectskin.pipeline.field.field_cache_dir`, ``$ECTSKIN_CACHE/fields`` or
        ``~/.cache/ectskin/fields``); shared by every output folder.
    field_grid : "quick" | "fine"
        The fields' grid (:data:`ectskin.twin.field_spec.FIELD_GRIDS`): "quick" builds the
        demo's 8 states in minutes and misses the field's accuracy bar near the chambers'
        walls and ends; "fine" meets it on nearly every point at about 4x the build time.
    field_states : "contact" | "all"
        The states whose fields the bound and the inversion read: those of the contact
        experiment (the default: the fields it is simulated from), or every state of the contact
        run's data (the paper's trials add the 10-ml states;
        :func:`~ectskin.pipeline.field.physics_field_specs`), so that the inversion answers every
        test frame, at the build time of the extra fields.
    bound_push_columns : "untouched" | "finger"
        Where the bound's push columns come from
        (:data:`ectskin.twin.bound_field.PUSH_COLUMNS`): the untouched state once per state (the
        default, seconds), or a table of direct solves with the finger pressing per state (about
        30 000 solves a state), without which the bound beyond the wire ends with the hand's
        push unknown is several times too low (docs/bound.md).
    inversion_finger : "auto" | "on" | "off"
        The inversion fits each pressing finger's pulp modulus and radius and pools them over
        each trial's frames, one person's (:mod:`ectskin.pipeline.inversion`): "auto" (the
        default) where the validation trials' point error says so, "on", or "off" (no finger
        tables built).
    """

    out_dir: Path
    profile: str = "quick"
    seed: int = 0
    workers: int | None = None
    force: bool = False
    protocol: Protocol | None = None
    recording: Recording | None = field(default=None, repr=False, compare=False)
    epochs: int | Mapping[str, int] | None = None
    ablations: bool = True
    baselines: bool = True
    characterize: bool = True
    robust: bool = True
    coverage: bool = True
    contact: bool = True
    touch_model: str = "mlp"
    device: str | None = None
    progress: bool = True
    threads: int | str | None = "auto"
    command: str | None = field(default=None, compare=False)
    figure_format: str = "png"
    dpi: int = DEFAULT_DPI
    contact_response: str = "field"
    field_cache: Path | None = field(default=None, compare=False)
    field_grid: str = "quick"
    field_states: str = "contact"
    bound_push_columns: str = "untouched"
    inversion_finger: str = "auto"

    def __post_init__(self) -> None:
        check_type("out_dir", self.out_dir, (str, os.PathLike))
        object.__setattr__(self, "out_dir", Path(self.out_dir))
        check_option("profile", self.profile, PROFILES)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise EctskinError(f"seed must be an integer, got {self.seed!r}")
        if self.workers is not None:
            _check_positive_int("workers", self.workers)
        if self.protocol is not None:
            check_type("protocol", self.protocol, Protocol)
        if self.recording is not None:
            check_type("recording", self.recording, Recording)
            if self.protocol is not None:
                raise EctskinError("give a protocol to simulate or a recording to use, not both")
        if isinstance(self.epochs, Mapping):
            unknown = sorted(set(self.epochs) - set(RUNS))
            if unknown:
                raise EctskinError(
                    f"epochs: unknown run name(s) {unknown}; allowed: {', '.join(RUNS)}"
                )
            for k, v in self.epochs.items():
                _check_positive_int(f"epochs[{k!r}]", v)
            object.__setattr__(self, "epochs", MappingProxyType(dict(self.epochs)))
        elif self.epochs is not None:
            _check_positive_int("epochs", self.epochs)
        check_option("touch_model", self.touch_model, TOUCH_MODELS)
        resolve_threads(self.threads)  # an invalid value fails here, before any work
        check_figure_options(self.figure_format, self.dpi)
        check_option("contact_response", self.contact_response, CONTACT_RESPONSES)
        check_option("field_grid", self.field_grid, tuple(FIELD_GRIDS))
        check_option("field_states", self.field_states, FIELD_STATES)
        check_option("bound_push_columns", self.bound_push_columns, BOUND_PUSH_COLUMNS)
        check_option("inversion_finger", self.inversion_finger, INVERSION_FINGER)
        if self.field_cache is not None:
            check_type("field_cache", self.field_cache, (str, os.PathLike))
            object.__setattr__(self, "field_cache", Path(self.field_cache))

    @property
    def run_names(self) -> tuple[str, ...]:
        """The runs this config trains, in training order."""
        return (
            ("touch",)
            + (("touch_robust",) if self.robust else ())
            + ("track",)
            + (tuple(ABLATIONS.values()) if self.ablations else ())
        )

    def contact_protocol(self) -> Protocol | None:
        """The contact experiment: the simulated protocol with the chambers at its lowest and
        highest level only, touches placed anywhere in their region, with lifts, hover and
        approach, a second finger in 30 % of the touch trials, drawn from its own random
        streams (:data:`CONTACT_STREAM`). Read from the states' response fields
        (``contact_response="field"``): :data:`CONTACT_TOUCH_TRIALS` touch trials per state,
        each pressing at a new point every :data:`CONTACT_DWELL_S` (60 in a 30-s trial) and
        sliding there in contact for :data:`CONTACT_SLIDE` of the dwell; solved
        (``"solve"``): 4 touch trials per state of 2 points each. None when a recording is
        given. (The contact model trains on these trials together with the paper's:
        :func:`ectskin.pipeline.contact.with_paper_trials`.)"""
        base = self.simulation_protocol()
        if base is None:
            return None
        levels = tuple(sorted({min(base.levels_ml), max(base.levels_ml)}))
        common: dict[str, Any] = dict(
            levels_ml=levels, touch_placement="uniform", lifts=True, hover=True, approach=True,
            second_finger=0.3, stream=CONTACT_STREAM,
        )
        if self.contact_response == "solve":
            return replace(base, touch_trials=4, touch_dwells=2, dwell_slide_s=0.0,
                           response="solve", **common)
        dwells = max(1, min(base.n_frames, int(round(base.duration_s / CONTACT_DWELL_S))))
        return replace(
            base,
            touch_trials=CONTACT_TOUCH_TRIALS,
            touch_dwells=dwells,
            dwell_slide_s=CONTACT_SLIDE * base.duration_s / dwells,
            response="field",
            **common,
        )

    def coverage_protocol(self) -> Protocol | None:
        """The coverage trials of the simulated protocol (:func:`ectskin.twin.coverage.
        coverage_protocol` on the paper's layout) that the ``robust`` run adds to its training
        split; None without a ``robust`` run or ``coverage``, or with a given recording."""
        base = self.simulation_protocol()
        if base is None or not (self.robust and self.coverage):
            return None
        return coverage_protocol(base, default_layout())

    def simulation_protocol(self) -> Protocol | None:
        """The protocol to simulate: ``protocol``, else the paper's with ``seed``; None when a
        recording is given."""
        if self.recording is not None:
            return None
        return self.protocol if self.protocol is not None else Protocol(seed=self.seed)

    @property
    def figure_settings(self) -> dict[str, Any]:
        """The figure options as the evaluation steps record them: empty for the defaults, so
        that folders made before the options existed are reused as they are."""
        if (self.figure_format, self.dpi) == ("png", DEFAULT_DPI):
            return {}
        return {"figures": {"format": self.figure_format, "dpi": self.dpi}}

    def run_profile(self, name: str) -> str:
        """The ``ectskin.learn.train`` profile run ``name`` trains with."""
        return RUN_PROFILES.get(name, self.profile)

    def epochs_for(self, name: str) -> int | None:
        """Epochs of run ``name``: from ``epochs`` (an int for all, or per run as documented
        above), else the profile's (None; ablations under ``quick``: :data:`QUICK_ABLATION_EPOCHS`).
        """
        epochs = self.epochs
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
        if self.profile == "quick" and name in ABLATIONS.values():
            return QUICK_ABLATION_EPOCHS
        return None
