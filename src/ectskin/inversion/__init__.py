"""Training-free physical inversion: fingers fitted to readouts through the response field.

``docs/inversion.md`` describes the model, its assumptions and the API:
:class:`Inversion` (``fit`` one frame), :func:`fit_frames` and :func:`invert_recording` (many),
:func:`push_basis` (the hand's push as nuisance columns, from direct solves);
:func:`pool_fingers` (one person's finger pooled over their frames) and :class:`FingerPool`
(the same frame by frame, for a stream; :mod:`ectskin.inversion.person`);
:class:`FingerGuess` (a guess that seeds a fit, :mod:`ectskin.inversion.seed`);
:mod:`ectskin.inversion.coupling` (two fingers as coupled conductors);
:func:`estimate_model_error` (what the field does not model, from the fits' residuals:
:mod:`ectskin.inversion.model_error`).
"""

from ectskin.inversion.fit import FingerEstimate, Inversion, InversionResult
from ectskin.inversion.frames import fit_frames, invert_recording, results_to_arrays
from ectskin.inversion.model import FieldLike, StateModel, push_basis
from ectskin.inversion.model_error import ModelError, RunningModelError, estimate_model_error
from ectskin.inversion.person import FingerPool, pool_fingers
from ectskin.inversion.seed import FingerGuess

__all__ = [
    "FieldLike",
    "FingerEstimate",
    "FingerGuess",
    "FingerPool",
    "Inversion",
    "InversionResult",
    "ModelError",
    "StateModel",
    "RunningModelError",
    "estimate_model_error",
    "fit_frames",
    "invert_recording",
    "pool_fingers",
    "push_basis",
    "results_to_arrays",
]
