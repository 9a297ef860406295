"""Guesses that seed the inversion's fit: :class:`FingerGuess` and :func:`seed_starts`.

A *seed* is one guess of the fingers on the skin, a sequence of 1 or 2 :class:`FingerGuess`
(its length is the guessed count), e.g. what a learned contact model answers for the same frame
(the hybrid of :mod:`ectskin.pipeline.contact_pick`). ``Inversion.fit(..., seeds=[seed, ...])``
fits each seed of k fingers as one more start of the k-finger fit, beside the coarse search's
(``Inversion(seed_search="add")``, the default: the best fit of all starts is kept, so a seed can
only lower that count's χ²), or in place of it (``"replace"``: the count's coarse search is
skipped where a seed gives it a start). A guess pressing (``force_n`` given) starts the
pressing mode at that force; one hovering (``height_mm`` given) the hovering mode at that height.
Points and forces or heights outside the field's ranges are clipped into them (as every start).
A seed with a face or mode the state's field lacks is left out (a model of two faces may guess a
face that a field of one does not cover).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError
from ectskin.inversion.model import MODES, StateModel

__all__ = ["SEED_SEARCH", "FingerGuess", "seed_starts"]

#: how seeds join the coarse search's starts (module docstring)
SEED_SEARCH = ("add", "replace")
#: the most fingers of one seed (the inversion fits at most two)
MAX_SEED_FINGERS = 2


@dataclass(frozen=True)
class FingerGuess:
    """A guess of one finger: its face, point (u, v) mm, and its force (N, pressing) or its
    height above the skin (mm, hovering): exactly one of ``force_n`` and ``height_mm``."""

    face: str
    u_mm: float
    v_mm: float
    force_n: float | None = None
    height_mm: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.face, str):
            raise EctskinError(f"FingerGuess: face must be a face name (str), got {self.face!r}")
        for name in ("u_mm", "v_mm"):
            v = getattr(self, name)
            if not (isinstance(v, int | float | np.floating) and math.isfinite(v)):
                raise EctskinError(f"FingerGuess: {name} must be a finite number, got {v!r}")
        if (self.force_n is None) == (self.height_mm is None):
            raise EctskinError(
                "FingerGuess: give exactly one of force_n (pressing) and height_mm (hovering), got "
                f"force_n={self.force_n!r}, height_mm={self.height_mm!r}")
        if self.force_n is not None and not math.isfinite(self.force_n):
            raise EctskinError(f"FingerGuess: force_n must be finite, got {self.force_n!r}")
        if self.height_mm is not None and not (math.isfinite(self.height_mm) and self.height_mm > 0):
            raise EctskinError(f"FingerGuess: height_mm must be a finite number > 0, got "
                               f"{self.height_mm!r}")

    @property
    def mode(self) -> str:
        return "contact" if self.force_n is not None else "hover"


def seed_starts(m: StateModel, seeds: Any, max_fingers: int
                ) -> dict[int, list[list[tuple[int, int, np.ndarray]]]]:
    """{count k: [start, ...]} of ``seeds`` (a sequence of seeds, each a sequence of 1 or 2
    :class:`FingerGuess`) in the state model ``m``: each start a list of (face index, mode
    index, (u, v, s)), s the force (pressing) or ln of the height (hovering), in the inversion's
    parameters. Seeds with a face or mode ``m`` lacks, or more fingers than ``max_fingers``, are
    left out."""
    if seeds is None:
        return {}
    if isinstance(seeds, FingerGuess) or not isinstance(seeds, Sequence):
        raise EctskinError("Inversion: seeds must be a sequence of seeds, each a sequence of "
                           f"FingerGuess, got {type(seeds).__name__}")
    out: dict[int, list[list[tuple[int, int, np.ndarray]]]] = {}
    for i, seed in enumerate(seeds):
        if (not isinstance(seed, Sequence) or not 1 <= len(seed) <= MAX_SEED_FINGERS
                or not all(isinstance(g, FingerGuess) for g in seed)):
            raise EctskinError(f"Inversion: seeds[{i}] must be a sequence of 1 to "
                               f"{MAX_SEED_FINGERS} FingerGuess, got {seed!r}")
        if len(seed) > max_fingers:  # a count the inversion does not fit
            continue
        if any(g.face not in m.faces or g.mode not in m.modes for g in seed):
            continue
        start = [(m.faces.index(g.face), MODES.index(g.mode),
                  np.array([g.u_mm, g.v_mm, g.force_n if g.force_n is not None
                            else math.log(float(g.height_mm or 1.0))], dtype=np.float64))
                 for g in seed]
        out.setdefault(len(seed), []).append(start)
    return out
