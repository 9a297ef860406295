"""Many frames at once: arrays of frames and whole recordings through the inversion.

:func:`fit_frames` inverts an array of frames (each with its state), :func:`results_to_arrays`
turns the results into arrays (one row per frame, two finger slots), and
:func:`invert_recording` does both for the trials of a :class:`~ectskin.io.recording.Recording`,
with each trial's inflation as its state: the call the reproduction, the report and the live
engine make.
"""

from __future__ import annotations

import time
from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin.inversion.fit import Inversion, InversionResult
from ectskin.inversion.model import FieldLike
from ectskin.inversion.person import POOL_SD_FLOOR, pool_fingers
from ectskin.io.recording import Recording
from ectskin.twin.pool import run_in_workers
from ectskin.twin.readout import ReadoutConfig

#: finger slots of the arrays (the inversion fits at most two fingers)
SLOTS = 2
#: frames per job when :func:`fit_frames` runs on several worker processes: enough to keep a
#: job's overhead (its results sent back) small against its fits (5-30 ms each), few enough
#: that the workers finish together
FRAMES_PER_JOB = 64

_WORK: dict[str, Any] = {}  # a worker's frames and inversion (set once per worker process)


def fit_frames(
    inversion: Inversion,
    readouts: Any,
    states: Any = None,
    *,
    window: int = 1,
    kind: str = "absolute",
    reference: Any = None,
    seeds: Sequence[Any] | None = None,
    workers: int = 1,
    person: Sequence[Hashable] | None = None,
    sd_floor: float = POOL_SD_FLOOR,
) -> tuple[list[InversionResult], np.ndarray]:
    """Invert every frame of ``readouts`` (n_frames, n_pairs), or of every trial of a
    :class:`~ectskin.io.recording.Recording` (each at its trial's inflation, windows within a
    trial; ``states`` not given); returns the results and the seconds each frame took
    (n_frames,).

    ``states``: one inflation vector for all frames, or (n_frames, n_chambers). ``window`` w:
    frame f is fitted to the mean of frames f − w + 1 … f (fewer at the start), its noise
    divided by √(frames averaged). ``kind`` and ``reference`` as :meth:`Inversion.fit`;
    ``seeds``: one entry per frame, that frame's ``seeds`` of :meth:`Inversion.fit` (None: none;
    arrays only). BLAS runs on one thread meanwhile (the products are tiny; threads only add
    overhead). ``workers`` > 1: the frames are fitted in that many processes
    (:func:`ectskin.twin.pool.run_in_workers`), :data:`FRAMES_PER_JOB` at a time; every fit
    depends on its own frames alone, so the results are the same as on one.

    ``person``: one label per frame (arrays only), whose finger pressed it (a trial, a
    session). The frames are fitted, each person's finger nuisances pooled over its frames
    (:func:`~ectskin.inversion.person.pool_fingers`, ``sd_floor``), and every frame of a person
    whose frames told something is fitted again with that as its ``finger`` prior; the seconds
    are both fits'. Without finger tables (``Inversion(modulus=, radius=)``) nothing is pooled
    and the results are those without ``person``.
    """
    if person is not None:
        return _fit_per_person(inversion, readouts, states, person, sd_floor, window=window,
                               kind=kind, reference=reference, seeds=seeds, workers=workers)
    return _fit(inversion, readouts, states, window=window, kind=kind, reference=reference,
                seeds=seeds, workers=workers)


def _fit(inversion: Inversion, readouts: Any, states: Any, *, window: int, kind: str,
         reference: Any, seeds: Sequence[Any] | None, workers: int,
         fingers: Sequence[Any] | None = None) -> tuple[list[InversionResult], np.ndarray]:
    """:func:`fit_frames` without ``person``; ``fingers``: per frame the ``finger`` prior of
    :meth:`Inversion.fit`, or None to skip the frame (its result None, its seconds 0)."""
    if isinstance(readouts, Recording):
        if states is not None or seeds is not None:
            raise EctskinError("fit_frames: a recording's trials carry their states; give no "
                               "states or seeds")
        parts = [_fit(inversion, t.capacitance, t.inflation, window=window, kind=kind,
                      reference=reference, seeds=None, workers=workers)
                 for t in readouts.trials]
        return ([r for res, _ in parts for r in res],
                np.concatenate([sec for _, sec in parts]) if parts else np.zeros(0))
    if states is None:
        raise EctskinError("fit_frames: states (the inflation of the frames) are needed with arrays")
    y = np.asarray(readouts, dtype=np.float64)
    if y.ndim != 2 or y.shape[1] != inversion.n_pairs:
        raise EctskinError(
            f"fit_frames: readouts must have shape (n_frames, {inversion.n_pairs}), got {y.shape}"
        )
    n = y.shape[0]
    s = np.asarray(states, dtype=np.float64)
    if s.ndim <= 1:
        s = np.broadcast_to(np.atleast_1d(s), (n, np.atleast_1d(s).size))
    if s.ndim != 2 or s.shape[0] != n:
        raise EctskinError(
            f"fit_frames: states must be one inflation vector or ({n}, n_chambers), got {s.shape}"
        )
    if not (isinstance(window, int) and window >= 1):
        raise EctskinError(f"fit_frames: window must be an integer >= 1, got {window!r}")
    if seeds is not None and len(seeds) != n:
        raise EctskinError(f"fit_frames: seeds must hold one entry per frame ({n}), got "
                           f"{len(seeds)}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise EctskinError(f"fit_frames: workers must be an integer >= 1, got {workers!r}")
    work = (inversion, y, s, window, kind, reference, seeds, fingers)
    spans = [(lo, min(lo + FRAMES_PER_JOB, n)) for lo in range(0, n, FRAMES_PER_JOB)]
    if workers == 1 or len(spans) < 2:
        return _fit_span(work, 0, n)
    parts = list(run_in_workers(_run_span, spans, workers=min(workers, len(spans)),
                                init=_set_work, initargs=(work,)))
    return [r for res, _ in parts for r in res], np.concatenate([sec for _, sec in parts])


def _fit_span(work: tuple, lo: int, hi: int) -> tuple[list[InversionResult], np.ndarray]:
    """Frames ``lo`` .. ``hi`` − 1 of :func:`fit_frames`' arguments ``work``, one by one."""
    inversion, y, s, window, kind, reference, seeds, fingers = work
    results: list[Any] = []  # InversionResult, or None for a frame skipped (fingers)
    seconds = np.zeros(hi - lo)
    with threadpool_limits(limits=1):  # the products are tiny: BLAS threads only cost
        for f in range(lo, hi):
            if fingers is not None and fingers[f] is None:
                results.append(None)
                continue
            t0 = time.perf_counter()
            results.append(inversion.fit(y[max(0, f - window + 1): f + 1], s[f], kind=kind,
                                         reference=reference,
                                         seeds=None if seeds is None else seeds[f],
                                         finger=None if fingers is None else fingers[f]))
            seconds[f - lo] = time.perf_counter() - t0
    return results, seconds


def _fit_per_person(inversion: Inversion, readouts: Any, states: Any, person: Sequence[Hashable],
                    sd_floor: float, **kw: Any) -> tuple[list[InversionResult], np.ndarray]:
    """:func:`fit_frames` with ``person``: fit, pool per person, refit."""
    if isinstance(readouts, Recording):
        raise EctskinError("fit_frames: person labels go with arrays of frames, not a "
                           "recording: give its frames and one label per frame (its trial)")
    first, seconds = _fit(inversion, readouts, states, **kw)
    n = len(first)
    if len(person) != n:
        raise EctskinError(f"fit_frames: person must hold one label per frame ({n}), got "
                           f"{len(person)}")
    prior_sd = inversion.finger_prior_sd
    if not prior_sd:
        return first, seconds
    frames: dict[Hashable, list[int]] = {}
    for i, label in enumerate(person):
        frames.setdefault(label, []).append(i)
    priors: list[Any] = [None] * n
    for idx in frames.values():
        pooled = pool_fingers([first[i] for i in idx], prior_sd, sd_floor=sd_floor)
        told = {q: v for q, v in pooled.items() if v != (0.0, float(prior_sd[q]))}
        for i in idx:
            priors[i] = told or None
    if all(p is None for p in priors):
        return first, seconds
    second, more = _fit(inversion, readouts, states, fingers=priors, **kw)
    return [b if b is not None else a for a, b in zip(first, second)], seconds + more


def _set_work(work: tuple) -> None:
    _WORK["work"] = work


def _run_span(span: tuple[int, int]) -> tuple[list[InversionResult], np.ndarray]:
    return _fit_span(_WORK["work"], *span)


def results_to_arrays(results: Sequence[InversionResult]) -> dict[str, np.ndarray]:
    """Arrays of the results, one row per frame and ``SLOTS`` finger slots (finger order as
    fitted; empty slots hold NaN, "" and False):

    ``n_fingers`` (F,) int, ``face`` (F, 2) str, ``contact`` (F, 2) bool, ``uv_mm`` (F, 2, 2),
    ``force_n`` / ``height_mm`` (F, 2), ``uv_se_mm`` (F, 2, 2), ``force_se_n`` /
    ``height_se_mm`` (F, 2), ``scale`` / ``scale_se`` (F, 2) (the finger's signal scale, 1 and 0
    without a scale nuisance), ``log_likelihood`` (F,), ``bic`` (F, 3) (per count, inf where not
    tried), ``converged`` (F,) bool.
    """
    n = len(results)
    out: dict[str, np.ndarray] = {
        "n_fingers": np.array([r.n_fingers for r in results], dtype=np.int64),
        "face": np.full((n, SLOTS), "", dtype="<U16"),
        "contact": np.zeros((n, SLOTS), bool),
        "uv_mm": np.full((n, SLOTS, 2), np.nan),
        "force_n": np.full((n, SLOTS), np.nan),
        "height_mm": np.full((n, SLOTS), np.nan),
        "uv_se_mm": np.full((n, SLOTS, 2), np.nan),
        "force_se_n": np.full((n, SLOTS), np.nan),
        "height_se_mm": np.full((n, SLOTS), np.nan),
        "point_se_noise_mm": np.full((n, SLOTS), np.nan),
        "scale": np.full((n, SLOTS), np.nan),
        "scale_se": np.full((n, SLOTS), np.nan),
        "log_likelihood": np.array([r.log_likelihood for r in results], dtype=np.float64),
        "bic": np.full((n, SLOTS + 1), np.inf),
        "converged": np.array([r.converged for r in results], dtype=bool),
    }
    for i, r in enumerate(results):
        out["bic"][i, : len(r.bic_by_count)] = r.bic_by_count
        for k, fe in enumerate(r.fingers):
            out["face"][i, k] = fe.face
            out["contact"][i, k] = fe.contact
            out["uv_mm"][i, k] = fe.u_mm, fe.v_mm
            out["force_n"][i, k] = fe.force_n
            out["height_mm"][i, k] = fe.height_mm
            out["uv_se_mm"][i, k] = fe.u_se_mm, fe.v_se_mm
            out["force_se_n"][i, k] = fe.force_se_n
            out["height_se_mm"][i, k] = fe.height_se_mm
            out["point_se_noise_mm"][i, k] = fe.point_se_noise_mm
            out["scale"][i, k] = fe.scale
            out["scale_se"][i, k] = fe.scale_se
    return out


def invert_recording(
    fields: Mapping[tuple[float, ...], FieldLike] | Inversion,
    recording: Recording,
    trials: Sequence[str] | None = None,
    *,
    window: int = 1,
    kind: str = "absolute",
    reference: Any = None,
    push: Mapping[tuple[float, ...], np.ndarray] | None = None,
    noise: ReadoutConfig | None = None,
) -> dict[str, np.ndarray]:
    """Invert the frames of ``recording``'s trials (``trials``: names, default all), each trial
    at its own inflation state; the arrays of :func:`results_to_arrays` for all frames in
    trial order, plus ``trial`` (F,) (index into ``recording.trials``), ``frame`` (F,) (index
    in its trial) and ``seconds`` (F,) (the time each frame's fit took).

    ``fields``: {state: field} (an :class:`Inversion` is built with ``push`` and ``noise``) or
    a ready :class:`Inversion`. Every chosen trial's state must have a field.
    """
    inv = fields if isinstance(fields, Inversion) else Inversion(fields, noise, push=push)
    if not isinstance(recording, Recording):
        raise EctskinError(
            f"invert_recording: recording must be a Recording, got {type(recording).__name__}"
        )
    if recording.n_pairs != inv.n_pairs:
        raise EctskinError(
            f"invert_recording: the recording has {recording.n_pairs} pairs, the fields "
            f"{inv.n_pairs}"
        )
    names = [t.name for t in recording.trials]
    chosen = list(range(len(names))) if trials is None else []
    for name in trials or ():
        if name not in names:
            raise EctskinError(f"invert_recording: the recording has no trial {name!r}")
        chosen.append(names.index(name))
    for i in chosen:
        inv.model(recording.trials[i].inflation)  # a state without a field fails here, first
    results: list[InversionResult] = []
    parts: dict[str, list[np.ndarray]] = {"trial": [], "frame": [], "seconds": []}
    for i in chosen:
        t = recording.trials[i]
        res, sec = fit_frames(inv, t.capacitance, t.inflation, window=window, kind=kind,
                              reference=reference)
        results += res
        parts["trial"].append(np.full(t.n_frames, i, dtype=np.int64))
        parts["frame"].append(np.arange(t.n_frames, dtype=np.int64))
        parts["seconds"].append(sec)
    out = results_to_arrays(results)
    for k, v in parts.items():
        out[k] = np.concatenate(v) if v else np.zeros(0, np.int64 if k != "seconds" else float)
    return out
