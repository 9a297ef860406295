"""Build a :class:`Recording` from instrument files: one trial from a capacitance export and a
Motive take (:func:`build_recording`), or many trials from a JSON manifest
(:func:`build_recording_from_manifest`, format in ``docs/instrument-import.md``)."""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.io.align.delay import estimate_delay, resample_markers
from ectskin.io.capmeter import CapmeterData, read_capmeter_csv
from ectskin.io.motive import MocapData, read_motive_csv
from ectskin.io.recording import Recording, Trial
from ectskin.layout import SensorLayout, default_layout, load_layout

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- one trial
def _match_markers(mocap: MocapData, layout: SensorLayout) -> np.ndarray:
    """Column of the take for every layout marker (layout order), matched by name.

    A layout marker matches the take's marker of the same name, else the one whose name after
    Motive's asset prefix is its name (``M1`` matches ``Skin:M1``). Every layout marker must be
    found exactly once and every marker of the take must be a layout marker; otherwise the import
    stops with an error naming the missing, extra and ambiguous markers. Markers are never
    assigned by their order in the file: a take missing M3 would give M3 the data of M4.
    """
    want = [m.name for m in layout.markers]
    have = list(mocap.marker_names)
    order: list[int] = []
    missing: list[str] = []
    ambiguous: list[str] = []
    for name in want:
        hits = [k for k, n in enumerate(have) if n == name] or [
            k for k, n in enumerate(have) if n.split(":")[-1] == name
        ]
        if not hits:
            missing.append(name)
        elif len(hits) > 1:
            ambiguous.append(f"{name} ({', '.join(have[k] for k in hits)})")
        else:
            order.append(hits[0])
    twice = sorted({have[k] for k in order if order.count(k) > 1})
    matched = set(order)
    extra = [n for k, n in enumerate(have) if k not in matched]
    if ambiguous or twice:
        extra = []  # unmatched because ambiguous: named there
    if missing or extra or ambiguous or twice:
        problems = []
        if missing:
            problems.append(f"missing from the take: {', '.join(missing)}")
        if extra:
            problems.append(f"not in the layout: {', '.join(extra)}")
        if ambiguous:
            problems.append(f"ambiguous: {'; '.join(ambiguous)}")
        if twice:
            problems.append(f"matched by two layout markers: {', '.join(twice)}")
        raise EctskinError(
            f"{mocap.path}: the take's markers ({', '.join(have)}) do not match the markers of "
            f"layout {layout.name!r} ({', '.join(want)}) by name; {'; '.join(problems)}. Markers "
            "are matched by name (M1 matches Skin:M1), never by their order: select the take's "
            "markers (marker_names=..., --markers on the command line) or name the layout's "
            "markers as in the take"
        )
    return np.asarray(order, dtype=np.int64)


def build_recording(
    capmeter: CapmeterData,
    mocap: MocapData | None,
    layout: SensorLayout,
    *,
    delay: str | float = "auto",
    trial_name: str | None = None,
    inflation: Sequence[float] = (),
    region: int = 0,
    max_delay_s: float = 0.5,
    delay_method: str = "regression",
    clock: str = "start",
    max_gap_frames: int = 1,
    meta: dict[str, Any] | None = None,
) -> Recording:
    """One-trial :class:`Recording` from a capacitance export and (optionally) a Motive take.

    Parameters
    ----------
    capmeter : from :func:`read_capmeter_csv`; its channels must be ``layout.n_pairs`` pairs in the
        ECT order. mocap : from :func:`read_motive_csv`, or None (no markers).
    layout : the sensor layout; the take's markers are matched to ``layout.markers`` by name
        (``M1`` matches ``Skin:M1``); a take whose markers do not match them one to one is
        refused, naming the missing and extra markers.
    delay : ``"auto"`` (estimate with :func:`estimate_delay`) or the delay in s (markers lag > 0).
    max_delay_s, delay_method : search range and method of the estimate (``delay="auto"``).
    trial_name : default the capacitance file's stem. inflation : chamber volumes p, ml.
    region : the touched region for the whole trial (0 = no touch); labels every frame.
    clock : ``"start"``: both recordings count from their first sample (devices started together);
        ``"file"``: the two files' times are already on one clock.
    max_gap_frames : see :func:`resample_markers`.

    The trial's timestamps count from its first frame (s). ``Trial.meta`` records the sources, the
    delay (and how it was found), the masked cells, the occlusions and, under ``timing``, what
    the reader did to the readout's time stamps (re-derived, resampled).
    """
    check_option("clock", clock, ("start", "file"))
    delay = _check_delay(delay)
    if capmeter.n_channels != layout.n_pairs:
        raise EctskinError(
            f"{capmeter.path}: {capmeter.n_channels} capacitance channels "
            f"({', '.join(capmeter.channels)}), but layout {layout.name!r} has "
            f"{layout.n_electrodes} electrodes = {layout.n_pairs} pairs"
        )
    region = int(region)
    if region != 0:
        layout.region(region)  # raises a clear error for an unknown region
    values = _layout_order(capmeter, layout)
    name = trial_name or Path(capmeter.path).stem
    cap_t = capmeter.timestamps - (capmeter.timestamps[0] if clock == "start" else 0.0)
    trial_meta: dict[str, Any] = {
        "kind": "touch" if region else "no_contact",
        "source_capacitance": capmeter.path,
        "capacitance_units": sorted(set(capmeter.units)),
        "masked": capmeter.mask_report.to_dict(),
        "clock": clock,
    }
    if capmeter.timing:  # time stamps re-derived or resampled (ectskin.io.capmeter.timing)
        trial_meta["timing"] = dict(capmeter.timing)
    markers = None
    if mocap is not None:
        markers = _aligned_markers(
            mocap,
            layout,
            name,
            cap_t,
            values,
            trial_meta,
            delay=delay,
            max_delay_s=max_delay_s,
            delay_method=delay_method,
            clock=clock,
            max_gap_frames=max_gap_frames,
        )
    elif delay != "auto":
        log.info("no motion capture: the delay %r is not used", delay)
    dead = _dead_channels(values, layout, capmeter.path)
    stored = values.copy()
    stored[:, dead] = np.nan  # left out of training: listed in rec.meta["unmeasured_pairs"]
    if dead:
        trial_meta["dropped_channels"] = [layout.pair_names[j] for j in dead]
    trial_meta.update(meta or {})
    trial = Trial(
        name=name,
        capacitance=stored,
        timestamps=cap_t - cap_t[0],
        labels=np.full(capmeter.n_frames, region, dtype=np.int16),
        inflation=tuple(float(v) for v in inflation),
        region=region,
        markers=markers,
        meta=trial_meta,
    )
    rate = capmeter.frame_rate_hz
    if not np.isfinite(rate):
        raise EctskinError(f"{capmeter.path}: need at least 2 frames to know the frame rate")
    rec_meta: dict[str, Any] = {"source": "ectskin import build"}
    if dead:
        rec_meta["unmeasured_pairs"] = dead
    return Recording(layout=layout, trials=[trial], frame_rate_hz=rate, meta=rec_meta)


def _dead_channels(values: np.ndarray, layout: SensorLayout, src: str) -> list[int]:
    """Pairs (layout order) that read 0 pF in every frame, or nothing at all, logged.

    Such a channel (not connected) passes the import but would fail training, where Eq. 2
    divides by its reference of 0: its readouts are stored as NaN and its pair is listed in
    ``rec.meta["unmeasured_pairs"]``, which every data set leaves out.
    """
    finite = np.isfinite(values)
    dead = np.flatnonzero(~finite.any(axis=0) | np.all(~finite | (values == 0), axis=0))
    if dead.size == values.shape[1]:
        raise EctskinError(f"{src}: no channel has a usable readout (each reads 0 pF or nothing)")
    for j in dead:
        log.warning(
            "%s: channel %s reads 0 pF (or nothing) in every frame, not connected?: left out "
            "(stored as NaN, listed in unmeasured_pairs)",
            src,
            layout.pair_names[j],
        )
    return [int(j) for j in dead]


def _check_delay(delay: Any) -> str | float:
    if isinstance(delay, str) and delay == "auto":
        return delay
    try:
        delay = float(delay)
    except (TypeError, ValueError):
        raise EctskinError(f"delay must be 'auto' or a number of seconds, got {delay!r}") from None
    if not np.isfinite(delay):
        raise EctskinError(f"delay must be finite, got {delay!r}")
    return delay


def _layout_order(capmeter: CapmeterData, layout: SensorLayout) -> np.ndarray:
    """The readouts (n_frames, n_pairs) in the layout's pair order (by name when they match)."""
    values = capmeter.values
    if capmeter.channels != layout.pair_names and set(capmeter.channels) == set(layout.pair_names):
        order = [capmeter.channels.index(nm) for nm in layout.pair_names]
        values = values[:, order]
        log.info("%s: channels reordered to the layout's pair order by name", capmeter.path)
    elif capmeter.pairs is None and capmeter.channels != layout.pair_names:
        log.info(
            "%s: channel names (%s, ...) are neither the layout's pair names nor electrode pairs; "
            "taking the file's column order as the layout's pair order",
            capmeter.path,
            ", ".join(capmeter.channels[:3]),
        )
    return values


def _aligned_markers(
    mocap: MocapData,
    layout: SensorLayout,
    name: str,
    cap_t: np.ndarray,
    values: np.ndarray,
    trial_meta: dict[str, Any],
    *,
    delay: str | float,
    max_delay_s: float,
    delay_method: str,
    clock: str,
    max_gap_frames: int,
) -> np.ndarray:
    """The take's markers (layout order) at the readout frames ``cap_t``, after the delay.

    Records the delay, how it was found and the occlusions in ``trial_meta``.
    """
    order = _match_markers(mocap, layout)
    pos = mocap.positions[:, order]
    mk_t = mocap.timestamps - (mocap.timestamps[0] if clock == "start" else 0.0)
    if delay == "auto":
        est = estimate_delay(cap_t, values, mk_t, pos, max_delay_s=max_delay_s, method=delay_method)
        delay_s = est.delay_s
        trial_meta.update(
            delay_source="estimated",
            delay_method=est.method,
            delay_score=est.score,
            delay_contrast=est.contrast,
            delay_at_bound=est.at_bound,
        )
    else:
        delay_s = float(delay)
        trial_meta["delay_source"] = "given"
    markers = resample_markers(mk_t, pos, cap_t, delay_s, max_gap_frames=max_gap_frames)
    outside = (cap_t + delay_s < mk_t[0]) | (cap_t + delay_s > mk_t[-1])
    if outside.any():
        log.warning(
            "trial %r: %d of %d frames fall outside the motion-capture take (markers NaN)",
            name,
            int(outside.sum()),
            len(cap_t),
        )
    names = [mocap.marker_names[k] for k in order]
    trial_meta.update(
        delay_s=float(delay_s),
        source_mocap=mocap.path,
        mocap_frame_rate_hz=mocap.frame_rate_hz,
        mocap_length_units=mocap.units,
        mocap_markers=names,
        occluded_frames={m: mocap.occlusions[m].n_occluded for m in names},
        frames_without_markers=int(np.isnan(markers).any(axis=(1, 2)).sum()),
    )
    return markers


# --------------------------------------------------------------------------- manifests
_TRIAL_KEYS = {
    "name",
    "capacitance",
    "mocap",
    "inflation",
    "region",
    "delay",
    "marker_names",
    "time_unit",
    "value_unit",
    "length_units",
    "time_order",
    "resample_hz",
}
_TOP_KEYS = {"layout", "max_delay_s", "delay_method", "clock", "strict", "trials"}


def build_recording_from_manifest(
    path: str | Path, layout: SensorLayout | None = None, *, strict: bool | None = None
) -> Recording:
    """A multi-trial :class:`Recording` from a JSON manifest of instrument files.

    The manifest (format in ``docs/instrument-import.md``)::

        {"layout": "my_layout.json",          # optional; default: the layout argument
         "max_delay_s": 0.5, "delay_method": "regression", "clock": "start", "strict": true,
         "trials": [
           {"name": "p000_touch07", "capacitance": "cap/p000_07.csv", "mocap": "mocap/p000_07.csv",
            "inflation": [0, 0, 0], "region": 7, "delay": "auto"},
           {"name": "p000_rest", "capacitance": "cap/p000_rest.csv", "inflation": [0, 0, 0]}]}

    Paths are relative to the manifest. Every trial is read, aligned and checked; the first
    problem is an :class:`EctskinError` naming the manifest entry and the file.
    """
    src = str(path)
    doc = _read_manifest(path)
    base = Path(path).parent
    if "layout" in doc:
        layout = load_layout(base / str(doc["layout"]))
    layout = layout or default_layout()
    settings = {
        "strict": bool(doc.get("strict", True)) if strict is None else strict,
        "max_delay_s": float(doc.get("max_delay_s", 0.5)),
        "clock": doc.get("clock", "start"),
        "delay_method": doc.get("delay_method", "regression"),
    }
    entries = doc.get("trials")
    if not isinstance(entries, list) or not entries:
        raise EctskinError(f"{src}: 'trials' must be a non-empty list of trial objects")
    trials = []
    unmeasured: set[int] = set()
    rate = None
    for k, e in enumerate(entries):
        where = f"{src}: trials[{k}]"
        rec = _manifest_trial(e, where, base, layout, settings)
        if rate is not None and abs(rec.frame_rate_hz / rate - 1) > 0.01:
            raise EctskinError(
                f"{where}: frame rate {rec.frame_rate_hz:.3f} Hz differs from the first trial's "
                f"{rate:.3f} Hz"
            )
        rate = rate or rec.frame_rate_hz
        trials.extend(rec.trials)
        unmeasured.update(rec.meta.get("unmeasured_pairs", []))
    meta: dict[str, Any] = {"source": "ectskin import build", "manifest": src}
    if unmeasured:  # a pair dead in one trial is left out of every trial's training data
        meta["unmeasured_pairs"] = sorted(unmeasured)
    return Recording(layout=layout, trials=trials, frame_rate_hz=rate, meta=meta)


def _read_manifest(path: str | Path) -> dict[str, Any]:
    """The manifest's JSON object, its top-level keys checked."""
    src = str(path)
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise EctskinError(f"cannot read manifest {src}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise EctskinError(
            f"{src}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    except UnicodeDecodeError:
        raise EctskinError(f"{src}: not UTF-8 text (is it a JSON manifest?)") from None
    if not isinstance(doc, dict):
        raise EctskinError(f"{src}: a manifest must be a JSON object with a 'trials' list")
    unknown = set(doc) - _TOP_KEYS
    if unknown:
        raise EctskinError(
            f"{src}: unknown field(s) {sorted(unknown)}; allowed: {sorted(_TOP_KEYS)}"
        )
    return doc


def _manifest_trial(
    e: Any, where: str, base: Path, layout: SensorLayout, settings: dict[str, Any]
) -> Recording:
    """The one-trial recording of manifest entry ``e``; errors name the entry (``where``)."""
    if not isinstance(e, dict):
        raise EctskinError(f"{where} must be an object, got {type(e).__name__}")
    unknown = set(e) - _TRIAL_KEYS
    if unknown:
        raise EctskinError(
            f"{where}: unknown field(s) {sorted(unknown)}; allowed: {sorted(_TRIAL_KEYS)}"
        )
    if "capacitance" not in e:
        raise EctskinError(f"{where}: missing field 'capacitance' (the readout CSV)")
    strict = settings["strict"]
    try:
        cap = read_capmeter_csv(
            base / str(e["capacitance"]),
            n_pairs=layout.n_pairs,
            strict=strict,
            time_unit=e.get("time_unit"),
            value_unit=e.get("value_unit"),
            time_order=e.get("time_order", "file"),
            resample_hz=e.get("resample_hz"),
        )
        mocap = None
        if e.get("mocap"):
            mocap = read_motive_csv(
                base / str(e["mocap"]),
                e.get("marker_names"),
                strict=strict,
                length_units=e.get("length_units"),
            )
        inflation = e.get("inflation", [])
        if not isinstance(inflation, list) or not all(
            isinstance(v, (int, float)) for v in inflation
        ):
            raise EctskinError(f"'inflation' must be a list of numbers (ml), got {inflation!r}")
        region = e.get("region", 0)
        if not isinstance(region, int) or isinstance(region, bool):
            raise EctskinError(f"'region' must be an integer, got {region!r}")
        return build_recording(
            cap,
            mocap,
            layout,
            delay=e.get("delay", "auto"),
            trial_name=e.get("name"),
            inflation=inflation,
            region=region,
            max_delay_s=settings["max_delay_s"],
            clock=settings["clock"],
            delay_method=settings["delay_method"],
        )
    except EctskinError as exc:
        raise EctskinError(f"{where} ({e.get('name', e['capacitance'])}): {exc}") from None
