"""Coverage trials: every touch region of an experiment in every one of its inflation states.

The paper's experiment (§3) touches six regions per inflation state, so each of the 18 regions
is touched in about a third of the 27 states, and a test trial is often a combination of region
and state that training never saw. How the inflation moves a region's touch signature is then
learnt from the other regions alone: on the twin's sliding reading, seed 0, the robust recipe's
errors are one such trial (region 8 at 0/0/20 ml, read as its neighbours 7 and 9 over the part
of the region nearest them).

The twin can show the model the missing combinations. :func:`coverage_protocol` derives from an
experiment's protocol a short one with the same states, body, finger, hand and readout that
touches every region of both faces in every state (:data:`COVERAGE_REPEATS` times): one point
held for ``duration_s`` (default :data:`COVERAGE_DURATION_S`), drawn uniformly inside the region, a force drawn as the
experiment draws it, and one no-contact trial per state (the calibration's rest readout of each
state). It draws from random streams of its own (:data:`COVERAGE_STREAM`), so it shares no draw
with the experiment. The robust touch recipe adds these trials to its training split
(``ectskin.learn.profiles.TrainConfig.extra_train``): never to validation or test, which stay
the experiment's trials.

What they cost and give on the twin is in BENCHMARKS.md; on a real skin they help only as far as
the twin matches it (the layout, the body and its inflation), which the user's own rest readouts
per state check (``ectskin characterize``).
"""

from __future__ import annotations

from dataclasses import replace

from ectskin._check import EctskinError
from ectskin.layout import SensorLayout
from ectskin.twin.protocol import Protocol

#: The random streams of coverage trials: stream ``COVERAGE_STREAM + protocol.stream``
#: (:meth:`Protocol.rng`), apart from the paper's (0) and the contact experiment's.
COVERAGE_STREAM = 0xC0
#: Seconds of one coverage trial (90 frames at 30 fps): long enough for the force to move over a
#: part of its range. Each trial is one readout model (about 11 method-of-moments solves, however
#: long it lasts), so the 18 × 27 × 4 touches cost about as much as the paper's sliding experiment.
COVERAGE_DURATION_S = 3.0
#: Touches of each region in each state: four points of the region, so that the trials show
#: where its borders lie at every inflation. Two touches left light presses 2 mm inside a border
#: misread where the readouts tell the side (the Cramér–Rao bound across the border 0.01-0.16 mm
#: there); four, on the sliding reading's seeds 0-2, cut seed 0's validation errors 36 -> 8
#: frames and raised the accuracy on the other seeds' coverage trials in all six pairings
#: (one touch 99.88 %, two 99.96 % on seed 0's validation before; BENCHMARKS.md).
COVERAGE_REPEATS = 4

__all__ = ["COVERAGE_DURATION_S", "COVERAGE_REPEATS", "COVERAGE_STREAM", "coverage_protocol"]


def coverage_protocol(
    protocol: Protocol,
    layout: SensorLayout,
    *,
    duration_s: float = COVERAGE_DURATION_S,
    repeats: int = COVERAGE_REPEATS,
) -> Protocol:
    """The coverage experiment of ``protocol`` on ``layout``: per inflation state one trial
    without contact and ``repeats`` × twice as many touch trials as the larger face has regions
    (front and back alternate, each face going through its regions in fresh random orders, so
    with faces of equal region counts, as the paper's layout has, every region is touched
    ``repeats`` times per state), one uniformly drawn point held per trial, no second finger, no
    lifts; every other setting as in ``protocol``. Refused for a layout without touch regions or
    with ``repeats`` < 1."""
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise EctskinError(f"coverage: repeats must be a whole number >= 1, got {repeats!r}")
    faces = {r.surface for r in layout.regions}
    per_face = max(
        (sum(r.surface == f for r in layout.regions) for f in ("front", "back")), default=0
    )
    if per_face == 0 or not faces & {"front", "back"}:
        raise EctskinError(
            f"coverage: layout {layout.name!r} has no touch regions on the front or back face"
        )
    return replace(
        protocol,
        touch_trials=2 * per_face * repeats,
        no_contact_trial=True,
        duration_s=float(duration_s),
        touch_dwells=1,
        dwell_slide_s=None,
        touch_placement="uniform",
        second_finger=0.0,
        lifts=False,
        stream=COVERAGE_STREAM + protocol.stream,
    )
