"""Shared fixtures and factories of the test suite.

* ``torch`` runs single-threaded in every test (results depend on the thread count; one thread is
  also the fast choice on the 2-core CI machine). Set once here, never at import time in a file.
* ``layout``: the paper's default layout.
* ``make_recording``: a factory of small synthetic recordings (states × regions, optional
  markers with occlusions), the one to use unless a test needs values of its own (the HDF5
  round-trip's special floats, the recorder's irregular timestamps).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Iterable, Sequence

import numpy as np
import pytest

from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout

LAYOUT = default_layout()


def pytest_sessionfinish(session, exitstatus):
    """In CI (``CI`` set) a skipped test fails the run: a test that skips there does not exist."""
    if not os.environ.get("CI") or exitstatus != 0:
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    skipped = reporter.stats.get("skipped", []) if reporter else []
    if skipped:
        names = ", ".join(r.nodeid for r in skipped[:10])
        reporter.write_line(f"CI: {len(skipped)} test(s) skipped, which CI does not allow: {names}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


@pytest.fixture(autouse=True, scope="session")
def _torch_one_thread():
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def layout():
    return LAYOUT


def synthetic_recording(
    n_frames: int = 12,
    seed: int = 0,
    *,
    states: Sequence[tuple[float, ...]] = ((0.0, 0.0, 0.0), (20.0, 0.0, 10.0)),
    regions: Iterable[int] = (2, 11, 7),
    markers: bool = True,
    occluded: Iterable[str] = ("s1_r2",),
    no_markers: Iterable[str] = ("s1_r11",),
    layout=LAYOUT,
) -> Recording:
    """Per inflation state a no-contact trial ``s{k}_rest`` and touch trials ``s{k}_r{region}``.

    Readouts are a per-pair base (0.5-2 pF) scaled by the state (×(1 + 0.2 k)) and the region
    (×(1 + 0.02 r)) plus 1 fF noise, so a class is recoverable from one frame; markers are random
    walks around a line of markers 10 mm apart. ``occluded`` trials have one NaN marker in the
    middle frame; ``no_markers`` trials have none.
    """
    rng = np.random.default_rng(seed)
    p, m = layout.n_pairs, layout.n_markers
    base = rng.uniform(0.5, 2.0, p)
    occluded, no_markers = set(occluded), set(no_markers)
    t = np.arange(n_frames) / 30
    trials = []
    for s, infl in enumerate(states):
        scale = 1.0 + 0.2 * s
        trials.append(
            Trial(
                f"s{s}_rest",
                base * scale + rng.normal(0, 1e-3, (n_frames, p)),
                t,
                np.zeros(n_frames),
                inflation=infl,
                markers=rng.normal(0, 1, (n_frames, m, 3)) if markers else None,
                meta={"kind": "no_contact"},
            )
        )
        for r in regions:
            walk = 10 * np.arange(m)[None, :, None] + np.cumsum(
                rng.normal(0, 0.3, (n_frames, m, 3)), 0
            )
            name = f"s{s}_r{r}"
            if name in occluded:
                walk[n_frames // 2, 1, :] = np.nan
            trials.append(
                Trial(
                    name,
                    base * scale * (1 + 0.02 * r) + rng.normal(0, 1e-3, (n_frames, p)),
                    t,
                    np.full(n_frames, r),
                    inflation=infl,
                    region=r,
                    markers=None if (name in no_markers or not markers) else walk,
                    meta={"kind": "touch"},
                )
            )
    return Recording(layout, trials, 30.0)


def flat_skin_recording(layout=LAYOUT, n_frames=60, n_trials=40, seed=0) -> Recording:
    """A flat skin whose readout is analytic in the finger's point: each pair's change is a
    Gaussian bump of the distance from the finger to the pair's own spot on the front face,
    times the force (so (u, v) and F are recoverable), on a per-pair base. Markers are random
    walks (for the tracking runs of a reproduction)."""
    rng = np.random.default_rng(seed)
    p = layout.n_pairs
    base = rng.uniform(0.5, 2.0, p)
    spots = np.column_stack([rng.uniform(-25, 25, p), rng.uniform(0, 120, p)])
    t = np.arange(n_frames) / 30
    trials = [
        Trial(
            "rest",
            base + rng.normal(0, 1e-5, (n_frames, p)),
            t,
            np.zeros(n_frames),
            inflation=(0.0, 0.0, 0.0),
            meta={"kind": "no_contact"},
            markers=rng.normal(0, 1, (n_frames, layout.n_markers, 3)),
            contact=np.zeros(n_frames, bool),
            finger_uv_mm=np.full((n_frames, 2), np.nan),
            finger_height_mm=np.full(n_frames, np.nan),
            force=np.zeros(n_frames),
        )
    ]
    front = [r for r in layout.regions if r.surface == "front"]
    for k in range(n_trials):
        reg = front[k % len(front)]
        uv = np.array([rng.uniform(*reg.u_mm), rng.uniform(*reg.v_mm)])
        force = np.linspace(0.5, 1.5, n_frames)
        d2 = ((spots - uv) ** 2).sum(1)
        bump = np.exp(-d2 / (2 * 30.0**2))
        c = base * (1 - 0.05 * force[:, None] * bump[None, :])
        trials.append(
            Trial(
                f"touch_{k}",
                c + rng.normal(0, 1e-5, c.shape),
                t,
                np.full(n_frames, reg.id),
                inflation=(0.0, 0.0, 0.0),
                region=reg.id,
                meta={"kind": "touch"},
                markers=10 * np.arange(layout.n_markers)[None, :, None]
                + np.cumsum(rng.normal(0, 0.3, (n_frames, layout.n_markers, 3)), 0),
                contact=np.ones(n_frames, bool),
                finger_uv_mm=np.repeat(uv[None], n_frames, 0),
                finger_height_mm=np.zeros(n_frames),
                force=force,
                finger_surface="front",
            )
        )
    return Recording(layout, trials, 30.0)



@pytest.fixture
def make_recording():
    """The :func:`synthetic_recording` factory."""
    return synthetic_recording


def _spawn_cli(argv: list[str], wait_for: str):
    """Start ``python -m ectskin.cli ARGV`` with its stderr read in a thread.

    Returns ``(proc, lines, seen, reader)``: the process, the stderr lines read so far, an event
    set once a line contains ``wait_for``, and the reading thread (join it to get every line).
    """
    proc = subprocess.Popen(
        [sys.executable, "-m", "ectskin.cli", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: list[str] = []
    seen = threading.Event()

    def reader():
        for line in proc.stderr:
            lines.append(line)
            if wait_for in line:
                seen.set()

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    return proc, lines, seen, thread


@pytest.fixture
def spawn_cli():
    """The :func:`_spawn_cli` helper: a real ``ectskin`` process with its stderr watched."""
    return _spawn_cli


@pytest.fixture
def contact_recording():
    """The :func:`flat_skin_recording` factory (per-frame finger ground truth)."""
    return flat_skin_recording
