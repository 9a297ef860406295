"""Press data sets the twin did not make: a generic NPZ (docs/import-format.md) from a forward
model of its own, imported through :func:`ectskin.io.generic.load_generic`.

Another layout: the generic import's virtual layout (one "front" face, no regions; n virtual
electrodes for n(n−1)/2 channels). Another body and readout: each channel j answers a finger at
p with force F by a Gaussian bump, c_j = c0_j (1 + d) (1 − a_j √F exp(−|p − m_j|² / 2 w_j²)),
its centre m_j, width w_j, gain a_j and rest value c0_j drawn at random, d a per-press drift.
Another noise: Student-t (3 degrees of freedom), ``noise`` times c0_j. Each press is one point
held for ``hold`` frames (force ramping 0.5 → 3 N), between ``gap`` frames without a finger;
a few groups hold rest frames only. Every pressing frame has class 1 (one class: the layout has
no regions to name).

``difference=True`` writes the readouts as differences c_t − c0 (difference imaging) instead.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def press_npz(
    path: Path,
    *,
    n_channels: int = 28,
    n_presses: int = 120,
    hold: int = 10,
    gap: int = 3,
    n_rest: int = 6,
    noise: float = 0.002,
    seed: int = 0,
    difference: bool = False,
    drift: float = 0.0,
) -> Path:
    rng = np.random.default_rng(seed)
    n_el = 2
    while n_el * (n_el - 1) // 2 < n_channels:
        n_el += 1
    width = 10.0 * n_el  # the virtual layout's face: u in [0, 10 n], v in [0, 30]
    centre = np.column_stack([rng.uniform(0, width, n_channels), rng.uniform(0, 30, n_channels)])
    w = rng.uniform(6.0, 18.0, n_channels)
    gain = rng.uniform(0.02, 0.08, n_channels)
    c0 = rng.uniform(0.5, 2.0, n_channels)
    rows: dict[str, list] = {k: [] for k in ("readouts", "group", "labels", "pos", "force")}

    def frames(g: str, p: np.ndarray | None, forces: np.ndarray) -> None:
        d = 1.0 + drift * rng.standard_normal(n_channels)
        for f in forces:
            c = c0 * d
            if p is not None and f > 0:
                bump = np.exp(-np.sum((p - centre) ** 2, axis=1) / (2 * w**2))
                c = c * (1.0 - gain * np.sqrt(f) * bump)
            c = c + noise * c0 * rng.standard_t(3, n_channels)
            on = p is not None and f > 0
            rows["readouts"].append(c - c0 if difference else c)
            rows["group"].append(g)
            rows["labels"].append(1 if on else 0)
            rows["pos"].append(p if on else np.full(2, np.nan))
            rows["force"].append(float(f) if on else 0.0)

    for r in range(n_rest):
        frames(f"rest{r}", None, np.zeros(2 * hold))
    for k in range(n_presses):
        p = np.array([rng.uniform(2, width - 2), rng.uniform(2, 28)])
        ramp = np.concatenate([np.zeros(gap), np.linspace(0.5, 3.0, hold), np.zeros(gap)])
        frames(f"press{k}", p, ramp)
    n = len(rows["group"])
    np.savez(
        path,
        readouts=np.asarray(rows["readouts"]),
        group=np.asarray(rows["group"], dtype=str),
        labels=np.asarray(rows["labels"]),
        contact=np.asarray(rows["labels"]) == 1,
        position_mm=np.asarray(rows["pos"]),
        force_n=np.asarray(rows["force"]),
        surface=np.where(
            np.char.startswith(np.asarray(rows["group"], dtype=str), "press"), "front", ""
        ),
        frame_rate_hz=30.0,
    )
    assert n == len(rows["readouts"])
    return path
