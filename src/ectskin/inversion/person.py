"""What one person's frames tell of their finger: the finger nuisances pooled over frames.

A person's fingertip does not change from frame to frame: its pulp's modulus x = ln(E / E0)
and its radius r = ln(R / R0) (:mod:`ectskin.inversion.finger_nuisance`) are the same in every
frame that person presses, while each frame alone, through its own Gaussian prior (the
population's spread of fingers, sd s0), tells them only roughly. :func:`pool_fingers` combines
the frames' fits into one posterior of each nuisance: each frame's fitted value μ_i and standard
error s_i (the bound at its solution, the prior included) are a Gaussian posterior whose
likelihood part has the precision l_i = 1/s_i² − 1/s0² (the prior's precision taken out) and the
information μ_i/s_i² (the prior is centred at 0). Over the frames

    P = 1/s0² + Σ l_i,   centre = (Σ μ_i / s_i²) / P,   sd = max(P^(−1/2), sd_floor),

the product of the frames' likelihoods with the prior once. Consecutive frames of a trial
repeat one point and one model error, so they are not independent and the product overstates
what they tell; ``sd_floor`` keeps the pooled sd from going below what the model can be trusted
to (:data:`POOL_SD_FLOOR`). The result is the ``finger`` prior of
:meth:`~ectskin.inversion.Inversion.fit`: refitted with it, every frame of the person shares
what the others told (:func:`~ectskin.inversion.fit_frames` ``person=``).

Only frames with one finger pressing carry the nuisances here (beside it a finger may hover:
a hovering finger has none); of two pressing fingers one cannot say whose frame it is.

A stream (the live engine) pools as it goes: :class:`FingerPool` adds each frame as it is
fitted, and the frame was fitted with the pool so far as its prior (centre c_p, sd s_p) rather
than the population's, so its likelihood part is taken out of that prior: precision
1/s_i² − 1/s_p², information μ_i/s_i² − c_p/s_p² (for c_p = 0, s_p = s0 the terms above). In the
linear-Gaussian case the running pool is then the batch one of the same frames, whatever prior
each was fitted with.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from ectskin._check import EctskinError
from ectskin.inversion.finger_nuisance import FINGER_NUISANCES
from ectskin.inversion.result import InversionResult

__all__ = ["POOL_SD_FLOOR", "FingerPool", "pool_fingers"]

#: the least sd of a pooled finger nuisance (ln units: 5 % of E or R); the frames of a trial
#: share their model's errors, so their product is not trusted below it
POOL_SD_FLOOR = 0.05


class FingerPool:
    """One person's finger nuisances pooled frame by frame (module docstring).

    ``prior_sd``: {name: the population prior's sd} (:attr:`Inversion.finger_prior_sd
    <ectskin.inversion.Inversion.finger_prior_sd>`); :meth:`add` a fitted frame, :meth:`prior`
    the ``finger`` prior for the next one (None while no frame has told anything: fit with the
    population's), :meth:`reset` for another person."""

    def __init__(self, prior_sd: Mapping[str, float], *, sd_floor: float = POOL_SD_FLOOR) -> None:
        if not isinstance(prior_sd, Mapping):
            raise EctskinError(f"FingerPool: prior_sd must be a mapping {{name: sd}}, got "
                               f"{type(prior_sd).__name__}")
        for name, sd in prior_sd.items():
            if name not in FINGER_NUISANCES or not (isinstance(sd, int | float)
                                                    and 0 < sd < math.inf):
                raise EctskinError(f"FingerPool: prior_sd[{name!r}] must be the prior sd (> 0) "
                                   f"of one of {list(FINGER_NUISANCES)}, got {sd!r}")
        if not (isinstance(sd_floor, int | float) and 0 <= sd_floor < math.inf):
            raise EctskinError(f"FingerPool: sd_floor must be a number >= 0, got {sd_floor!r}")
        self.prior_sd = {name: float(sd) for name, sd in prior_sd.items()}
        self.sd_floor = float(sd_floor)
        self.reset()

    def reset(self) -> None:
        """Forget every frame: the population's prior again."""
        self._precision = {name: 1.0 / sd**2 for name, sd in self.prior_sd.items()}
        self._info = dict.fromkeys(self.prior_sd, 0.0)
        self._told = dict.fromkeys(self.prior_sd, 0)
        #: frames added that told at least one nuisance
        self.n_frames = 0

    def add(self, result: InversionResult,
            used: Mapping[str, tuple[float, float]] | None = None) -> bool:
        """Add a frame fitted with the prior ``used`` ({name: (centre, sd)}, what
        :meth:`prior` gave; None or a name missing: the population's (0, sd)); whether it told
        anything (one finger pressing, with the nuisance fitted)."""
        if not isinstance(result, InversionResult):
            raise EctskinError(f"FingerPool: results must be InversionResults, got "
                               f"{type(result).__name__}")
        pressing = [f for f in result.fingers if f.contact]
        if len(pressing) != 1:
            return False
        e, told = pressing[0], False
        for name, sd0 in self.prior_sd.items():
            mu, se = getattr(e, f"{name}_ln"), getattr(e, f"{name}_ln_se")
            if not (math.isfinite(mu) and math.isfinite(se) and se > 0):
                continue  # not fitted in this frame
            centre, sd = (used or {}).get(name, (0.0, sd0))
            self._precision[name] += max(1.0 / se**2 - 1.0 / float(sd) ** 2, 0.0)
            self._info[name] += mu / se**2 - float(centre) / float(sd) ** 2
            self._told[name] += 1
            told = True
        self.n_frames += told
        return told

    def posterior(self) -> dict[str, tuple[float, float]]:
        """{name: (centre, sd)} of every nuisance: the pool, its sd held at the floor; a
        nuisance no frame told keeps the population's prior (0, sd), exactly."""
        return {name: (self._info[name] / p, max(1.0 / math.sqrt(p), self.sd_floor))
                if self._told[name] else (0.0, self.prior_sd[name])
                for name, p in self._precision.items()}

    def prior(self) -> dict[str, tuple[float, float]] | None:
        """The ``finger`` prior of :meth:`Inversion.fit <ectskin.inversion.Inversion.fit>` for
        the next frame, or None while no frame told anything."""
        return self.posterior() if self.n_frames else None


def pool_fingers(results: Iterable[InversionResult], prior_sd: Mapping[str, float], *,
                 sd_floor: float = POOL_SD_FLOOR) -> dict[str, tuple[float, float]]:
    """{name: (centre, sd)} of each finger nuisance in ``prior_sd`` {name: the population
    prior's sd that the fits were made with}, pooled over the one-pressing-finger ``results``
    of one person (module docstring); a nuisance no frame resolved keeps its prior (0, sd),
    exactly."""
    pool = FingerPool(prior_sd, sd_floor=sd_floor)
    for r in results:
        pool.add(r)
    return pool.posterior()
