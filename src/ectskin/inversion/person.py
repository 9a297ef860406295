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

Only frames with one finger, pressing, carry the nuisances here: a hovering finger has none,
and of two pressing fingers one cannot say whose frame it is.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from ectskin._check import EctskinError
from ectskin.inversion.finger_nuisance import FINGER_NUISANCES
from ectskin.inversion.result import InversionResult

__all__ = ["POOL_SD_FLOOR", "pool_fingers"]

#: the least sd of a pooled finger nuisance (ln units: 5 % of E or R); the frames of a trial
#: share their model's errors, so their product is not trusted below it
POOL_SD_FLOOR = 0.05


def pool_fingers(results: Iterable[InversionResult], prior_sd: Mapping[str, float], *,
                 sd_floor: float = POOL_SD_FLOOR) -> dict[str, tuple[float, float]]:
    """{name: (centre, sd)} of each finger nuisance in ``prior_sd`` {name: the population
    prior's sd that the fits were made with}, pooled over the one-pressing-finger ``results``
    of one person (module docstring); a nuisance no frame resolved keeps its prior (0, sd),
    exactly."""
    if not isinstance(prior_sd, Mapping):
        raise EctskinError(f"pool_fingers: prior_sd must be a mapping {{name: sd}}, got "
                           f"{type(prior_sd).__name__}")
    for name, sd in prior_sd.items():
        if name not in FINGER_NUISANCES or not (isinstance(sd, int | float)
                                                and 0 < sd < math.inf):
            raise EctskinError(f"pool_fingers: prior_sd[{name!r}] must be the prior sd (> 0) of "
                               f"one of {list(FINGER_NUISANCES)}, got {sd!r}")
    if not (isinstance(sd_floor, int | float) and 0 <= sd_floor < math.inf):
        raise EctskinError(f"pool_fingers: sd_floor must be a number >= 0, got {sd_floor!r}")
    precision = {name: 1.0 / float(sd) ** 2 for name, sd in prior_sd.items()}
    info = dict.fromkeys(prior_sd, 0.0)
    told = dict.fromkeys(prior_sd, 0)
    for r in results:
        if not isinstance(r, InversionResult):
            raise EctskinError(f"pool_fingers: results must be InversionResults, got "
                               f"{type(r).__name__}")
        if r.n_fingers != 1 or not r.fingers[0].contact:
            continue
        e = r.fingers[0]
        for name in precision:
            mu, se = getattr(e, f"{name}_ln"), getattr(e, f"{name}_ln_se")
            if not (math.isfinite(mu) and math.isfinite(se) and se > 0):
                continue  # not fitted in this frame
            precision[name] += max(1.0 / se**2 - 1.0 / float(prior_sd[name]) ** 2, 0.0)
            info[name] += mu / se**2
            told[name] += 1
    return {name: (info[name] / p, max(1.0 / math.sqrt(p), float(sd_floor))) if told[name]
            else (0.0, float(prior_sd[name])) for name, p in precision.items()}
