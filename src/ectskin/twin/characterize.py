"""Characterisation of the e-skin in the twin: the paper's §2.2, Fig. 3 and Fig. 4.

* Inflation: the manipulator inflates from rest to ``inflation`` (paper: (20, 20, 20) ml); the
  calibrated change c = (c_t − c_0)/c_0 (Eq. 2, c_0 = uninflated) of every pair. Same-face pairs
  rise (electrode area grows), cross-face pairs fall (the faces move apart).
* Two-stage: inflate to ``touch_inflation`` (paper: (0, 20, 20)), then touch a region.
* For every region: its calibrated change (against the uninflated reference), the touch-only
  change (against the inflated, untouched state) and the bending-only change (the touch's
  mechanics without the finger in the field) at ``force_n``.

Values in ``characterize.json`` are noise-free (the model's true capacitance); the figures show
the measured signal (readout noise and quantisation included).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from ectskin._files import save_figure_atomic, write_json_atomic
from ectskin.io.calibration import relative_change
from ectskin.layout import SensorLayout, default_layout
from ectskin.twin.human import finger_path
from ectskin.twin.mechanics import Handling, Touch
from ectskin.twin.protocol import Protocol, region_bounds
from ectskin.twin.readout import ReadoutConfig, noise_pf, readout, snr_db
from ectskin.twin.response import TouchResponse
from ectskin.twin.sensor import SensorModel
from ectskin.viz import DEFAULT_DPI, check_figure_options, figure_file
from ectskin.viz.twin import plot_response

log = logging.getLogger(__name__)


def _ramp_capacitance(sensor, p_start, p_end, fractions):
    """(len(fractions), n_pairs) capacitance along a linear inflation path."""
    p_start, p_end = np.asarray(p_start, float), np.asarray(p_end, float)
    return np.stack([sensor.capacitance(p_start + f * (p_end - p_start))[0] for f in fractions])


def _selected_pairs(change: np.ndarray, same: np.ndarray) -> list[int]:
    """Two same-face pairs with the largest rise and two cross-face pairs with the largest fall."""
    same_idx = np.flatnonzero(same)
    cross_idx = np.flatnonzero(~same)
    rise = same_idx[np.argsort(-change[same_idx])][:2].tolist()
    fall = cross_idx[np.argsort(change[cross_idx])][:2].tolist()
    return rise + fall


def characterize(
    out_dir: str | Path | None = None,
    *,
    inflation=(20.0, 20.0, 20.0),
    touch_inflation=(0.0, 20.0, 20.0),
    force_n: float = 1.0,
    figure_region: int | None = None,
    layout: SensorLayout | None = None,
    sensor: SensorModel | None = None,
    readout_config: ReadoutConfig | None = None,
    seed: int = 0,
    figure_format: str = "png",
    dpi: int = DEFAULT_DPI,
) -> dict:
    """Compute the characterisation; with ``out_dir`` also write the figures and JSON.

    Returns the dict written to ``characterize.json``.
    """
    figure_format, dpi = check_figure_options(figure_format, dpi)
    layout = layout or (sensor.layout if sensor else default_layout())
    sensor = sensor or SensorModel(layout)
    man = sensor.manipulator
    p_full = man.check_inflation(inflation)
    p_touch = man.check_inflation(touch_inflation)
    rest = np.zeros_like(p_full)
    c0 = sensor.capacitance(rest)[0]
    c_full = sensor.capacitance(p_full)[0]
    c_part = sensor.capacitance(p_touch)[0]
    change_full = relative_change(c_full, c0)  # Eq. 2
    change_part = relative_change(c_part, c0)
    same = layout.same_surface
    names = [e.name for e in layout.electrodes]
    cfg = readout_config or ReadoutConfig()
    noise, snr = noise_pf(c0, cfg), snr_db(c0, cfg)
    pairs = [
        {
            "pair": layout.pair_names[k],
            "electrodes": [names[i], names[j]],
            "same_face": bool(same[k]),
            "standing_pf": float(c0[k]),
            "noise_ff": float(noise[k] * 1000.0),
            "snr_db": float(snr[k]),
            "inflation_change": float(change_full[k]),
        }
        for k, (i, j) in enumerate(layout.pairs)
    ]
    touches = []
    for reg in layout.regions:
        touch = Touch(reg.surface, reg.centre_mm)
        c_t = sensor.capacitance(p_touch, touch, [force_n])[0]
        c_b = sensor.capacitance(p_touch, touch, [force_n], with_finger=False)[0]
        touches.append(
            {
                "region": reg.id,
                "surface": reg.surface,
                "uv_mm": list(reg.centre_mm),
                "change": relative_change(c_t, c0).tolist(),
                "touch_only_change": relative_change(c_t, c_part).tolist(),
                "bending_only_change": relative_change(c_b, c_part).tolist(),
            }
        )
    result = {
        "pair_names": list(layout.pair_names),
        "inflation_ml": p_full.tolist(),
        "touch_inflation_ml": p_touch.tolist(),
        "touch_force_n": float(force_n),
        "pairs": pairs,
        "readout": {
            "resolution_ff": cfg.resolution_pf * 1000.0,
            "samples_per_frame": cfg.samples_per_frame,
            "output_step_ff": cfg.output_step_pf * 1000.0,
            "snr_db_min": float(snr.min()),
        },
        "inflation_change_max_abs": float(np.abs(change_full).max()),
        "partial_inflation_change": change_part.tolist(),
        "partial_vs_full_correlation": float(np.corrcoef(change_part, change_full)[0, 1]),
        "touches": touches,
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        region = figure_region or next(
            (r.id for r in layout.regions if r.surface == "front"), layout.regions[0].id
        )
        _write_figures(
            out, sensor, p_full, p_touch, region, force_n, change_full, same, cfg, seed,
            figure_format, dpi,
        )
        write_json_atomic(out / "characterize.json", result)
        log.info("characterisation written to %s", out)
    return result


def _write_figures(
    out, sensor, p_full, p_touch, region, force_n, change_full, same, cfg, seed, fmt, dpi
):
    layout = sensor.layout
    fps = 30.0
    rng = np.random.default_rng([seed, 4])
    phase = rng.uniform(0, 2 * np.pi, layout.n_pairs)
    selected = _selected_pairs(change_full, same)
    rest = np.zeros_like(p_full)
    fr = np.linspace(0, 1, 9)

    # Fig. 3: rest 3 s, inflate over 12 s, hold 5 s
    t = np.arange(int(20 * fps)) / fps
    frac = np.clip((t - 3.0) / 12.0, 0, 1)
    c_ramp = CubicSpline(fr, _ramp_capacitance(sensor, rest, p_full, fr), axis=0)(frac)
    meas = readout(c_ramp, t, rng, cfg, phase)
    c0 = meas[: int(3 * fps)].mean(axis=0)
    fig = plot_response(
        t, relative_change(meas, c0), list(layout.pair_names), selected,
        title=f"inflation to p = {tuple(p_full.tolist())} ml",
        stages=[(3.0, "inflate"), (15.0, "hold")],
    )
    save_figure_atomic(fig, out / figure_file("fig3_inflation", fmt), dpi=dpi)

    # Fig. 4: rest 3 s, inflate to p_touch over 9 s, hold; from 15 s a finger comes down onto
    # the region's centre (sensed before contact), presses for ~10 s with a human force (slow
    # wander and tremor around force_n, a little roll and slide) and leaves again by 27 s
    t = np.arange(int(30 * fps)) / fps
    frac = np.clip((t - 3.0) / 9.0, 0, 1)
    c = CubicSpline(fr, _ramp_capacitance(sensor, rest, p_touch, fr), axis=0)(frac)
    reg = layout.region(region)
    lo, hi = region_bounds(reg, 0.15)
    touch_frames = np.flatnonzero((t >= 15.0) & (t < 27.0))
    proto = Protocol(
        force_range_n=(0.5 * force_n, 1.5 * force_n), approach=True, push_max_n=0.0,
        approach_s=1.5, touch_dwells=1,
    )
    path = finger_path(
        touch_frames.size, fps, np.asarray([reg.centre_mm]), lo, hi, proto, rng
    )
    response = TouchResponse(sensor, p_touch, reg.surface, path, Handling(), None, proto)
    c[touch_frames] = response(path, Handling())
    meas = readout(c, t, rng, cfg, phase)
    c0 = meas[: int(3 * fps)].mean(axis=0)
    on = touch_frames[path.contact]
    fig = plot_response(
        t, relative_change(meas, c0), list(layout.pair_names), selected,
        title=f"two-stage: inflate to {tuple(p_touch.tolist())} ml, then touch region {region}",
        stages=[(3.0, "inflate"), (15.0, "approach"), (t[on[0]], "touch"), (t[on[-1]], "lift")],
    )
    save_figure_atomic(fig, out / figure_file("fig4_touch", fmt), dpi=dpi)

