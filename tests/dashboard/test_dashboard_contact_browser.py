"""End to end in headless Chromium: the Contact panel follows a replayed recording.

The recording is synthetic: a rest trial (the reference), a finger pressing region 3 (front) with a
rising force, a finger hovering over region 14 (back), and two fingers on regions 10 and 18 (back).
Each region moves its own 7 channels (disjoint patterns), so the stand-ins read each finger's force
exactly: the contact stand-in puts a finger at the centre of every pressed region with that force
(a hover when the pattern is faint) and the imager stand-in draws a bump at each centre. The page
must put the dots at those centres on the right face, with the uncertainty circle, move the force
bars, light the hover indicator, and draw the heat map where the bump is (and not elsewhere).

Needs Chromium and Playwright (the ``chromium`` fixture of ``conftest.py``: skipped without them
outside CI, failed in CI).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ectskin.dashboard import DashboardServer
from ectskin.io.hdf5 import RecordingWriter
from ectskin.layout import default_layout
from ectskin.learn.predict import ContactReading, FingerEstimate
from ectskin.live import LiveEngine, open_source

pytestmark = pytest.mark.browser

LAYOUT = default_layout()
RATE_HZ = 30.0
N = 45  # frames per trial
GAIN = 0.1  # calibrated change per newton along a region's (unit) pattern
PRESS, HOVER, PAIR = 3, 14, (10, 18)
USED = (PRESS, HOVER, *PAIR)
EXTENT = {"front": [[-20.0, 20.0], [5.0, 115.0]], "back": [[-20.0, 20.0], [5.0, 115.0]]}
NU, NV = 16, 44  # the imager's grid per face: 2.5 mm pixels
SCREENSHOT = Path("/tmp/dashboard_contact.png")


def _patterns() -> dict[int, np.ndarray]:
    """Region → (n_pairs,) unit pattern on its own 7 channels."""
    pats = {}
    for j, r in enumerate(USED):
        p = np.zeros(LAYOUT.n_pairs)
        p[7 * j : 7 * j + 7] = 1.0
        pats[r] = p / np.linalg.norm(p)
    return pats


PATTERNS = _patterns()
BASE = 1.0 + np.random.default_rng(0).uniform(0.0, 1.0, LAYOUT.n_pairs)  # pF


def _centre(r: int) -> tuple[str, float, float]:
    reg = LAYOUT.region(r)
    return reg.surface, float(reg.centre_mm[0]), float(reg.centre_mm[1])


def _forces(c: np.ndarray) -> dict[int, float]:
    """Region → force (N) read from a calibrated frame (exact: the patterns are disjoint)."""
    return {r: float(p @ c) / GAIN for r, p in PATTERNS.items()}


def write_recording(path: Path) -> Path:
    rng = np.random.default_rng(1)
    t = np.arange(N) / RATE_HZ

    def frames(force_by_region: dict[int, np.ndarray]) -> np.ndarray:
        c = np.zeros((N, LAYOUT.n_pairs))
        for r, f in force_by_region.items():
            c += GAIN * f[:, None] * PATTERNS[r]
        return BASE * (1 + c + rng.normal(0, 1e-5, c.shape))

    ramp = np.linspace(0.5, 1.5, N)
    with RecordingWriter(path, LAYOUT, RATE_HZ) as w:
        w.start_trial("rest", inflation=(0, 0, 0), region=0)
        w.append(frames({}), t, np.zeros(N, dtype=int))
        w.start_trial("press", inflation=(0, 0, 0), region=PRESS)
        w.append(frames({PRESS: ramp}), t, np.full(N, PRESS))
        w.start_trial("hover", inflation=(0, 0, 0), region=0)
        w.append(frames({HOVER: np.full(N, 0.15)}), t, np.zeros(N, dtype=int))
        w.start_trial("pair", inflation=(0, 0, 0), region=PAIR[0])
        w.append(
            frames({PAIR[0]: np.full(N, 0.8), PAIR[1]: np.full(N, 1.2)}), t, np.full(N, PAIR[0])
        )
    return path


class TemplateContact:
    """``ContactPredictor`` stand-in: a finger (sigma 2 + r/10 mm) at the centre of each region
    pressed with more than 0.3 N; none but a hover (p 0.9) when the strongest is 0.05-0.3 N."""

    n_pairs = LAYOUT.n_pairs
    window = 3
    faces = ["front", "back"]
    face_extent = EXTENT

    def read(self, w: np.ndarray) -> ContactReading:
        forces = _forces(w[-1])
        on = [r for r in sorted(forces) if forces[r] > 0.3]
        fingers = tuple(FingerEstimate(*_centre(r), 2.0 + r / 10, forces[r]) for r in on)
        top = max(forces.values())
        hover = 0.9 if not on and top > 0.05 else 0.02
        return ContactReading(len(on), 0.95 if on else 0.05, hover, fingers)


class BumpImager:
    """ECT imager stand-in: a Gaussian bump (6 mm) at each region's centre, its height the
    region's force; the peak is the strongest region's centre."""

    faces = ["front", "back"]
    grid_extent = EXTENT
    u = np.linspace(-20.0, 20.0, NU + 1)[:-1] + 1.25  # pixel centres, mm
    v = np.linspace(5.0, 115.0, NV + 1)[:-1] + 1.25

    def image(self, dc: np.ndarray) -> dict[str, np.ndarray]:
        out = {f: np.zeros((NV, NU)) for f in self.faces}
        for r, f in _forces(dc / BASE).items():
            face, u0, v0 = _centre(r)
            d2 = (self.u[None, :] - u0) ** 2 + (self.v[:, None] - v0) ** 2
            out[face] += f * np.exp(-d2 / (2 * 6.0**2))
        return out

    def locate(self, dc: np.ndarray) -> tuple[str, float, float, float]:
        forces = _forces(dc / BASE)
        r = max(forces, key=forces.get)
        return (*_centre(r), forces[r])


# One consistent look at the panel, taken inside the page (frames keep arriving meanwhile).
SNAPSHOT = """() => {
  const s = window.ectskinDashboard.state;
  const dots = [...document.querySelectorAll('#contact-faces .finger-dot[visibility="visible"]')]
    .map(d => ({ face: d.closest('.cface').dataset.face, k: Number(d.dataset.finger),
                 cx: Number(d.getAttribute('cx')), cy: Number(d.getAttribute('cy')),
                 ring: Number(d.ownerSVGElement.querySelector(
                   '.finger-sigma[data-finger="' + d.dataset.finger + '"]').getAttribute('r')) }));
  const rows = [...document.querySelectorAll('#contact-fingers .cf-row')].map(r => ({
    force: r.dataset.force === '' ? null : Number(r.dataset.force),
    width: parseFloat(r.querySelector('.bar').style.width) }));
  const hov = document.getElementById('hover-indicator');
  return { count: document.getElementById('contact-count').dataset.count, dots, rows,
           scale: Number(document.getElementById('force-scale').dataset.scale),
           hover: hov.dataset.state, p_hover: hov.dataset.p === '' ? null : Number(hov.dataset.p),
           hover_width: parseFloat(document.getElementById('hover-bar').style.width),
           contact: s.contact };
}"""

# The heat map of the front face once the newest image peaks at (u, v) with a finger there: alpha and colour of the
# canvas pixels under each point (u, v) mm; null until then (read in one go: frames keep coming).
HEAT_AT = """([u, v, points]) => {
  const e = window.ectskinDashboard.state.ect;
  if (!e || e.face !== 'front' || Math.abs(e.u_mm - u) > 0.01 || Math.abs(e.v_mm - v) > 0.01
      || !(e.peak > 0.3)) return null;  // the finger pressing (not noise peaking there at rest)
  const c = document.querySelector('#contact-faces canvas.heat[data-face="front"]');
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  return { w: c.width, h: c.height, ect: e,
    px: points.map(([pu, pv]) => {
      const x = Math.floor((pu + 20) / 40 * c.width);
      const y = c.height - 1 - Math.floor((pv - 5) / 110 * c.height);
      const i = 4 * (y * c.width + x);
      return { r: d[i], g: d[i + 1], b: d[i + 2], a: d[i + 3] }; }) };
}"""


def test_contact_panel_follows_a_replayed_recording(tmp_path, chromium):
    rec = write_recording(tmp_path / "contact.h5")
    source = open_source(f"replay:{rec}", speed=1.0, loop=True)
    engine = LiveEngine(
        source, contact=TemplateContact(), imager=BumpImager(), ect_every=2, reference_frames=30
    )
    errors: list[str] = []
    with DashboardServer(engine, port=0) as server:
        page = chromium.new_page(viewport={"width": 1400, "height": 1800})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(server.url)
        page.wait_for_selector('#connection-status[data-state="open"]', timeout=10_000)
        assert page.locator("#contact-panel").is_visible()
        assert page.locator("#contact-faces svg").count() == 2
        assert page.locator("#contact-faces canvas.heat").count() == 2
        assert page.locator("#contact-fingers .cf-row").count() == 2
        # the existing views are still there
        assert page.locator("#faces .region").count() == 18

        # One finger on region 3's centre (front), its circle of radius sigma, its force bar.
        face, u, v = _centre(PRESS)
        press = f"""() => {{ const s = ({SNAPSHOT})();
            return s.count === '1' && s.dots.length === 1 && s.dots[0].face === '{face}'
                   ? s : null; }}"""
        forces = set()
        for _ in range(3):  # the force rises during the trial: the bar follows
            snap = page.wait_for_function(press, timeout=15_000).json_value()
            (dot,) = snap["dots"]
            assert (dot["cx"], -dot["cy"]) == (
                pytest.approx(u, abs=0.01),
                pytest.approx(v, abs=0.01),
            )
            assert dot["ring"] == pytest.approx(2.0 + PRESS / 10, abs=0.01)
            row = snap["rows"][0]
            assert 0.45 < row["force"] < 1.55 and snap["rows"][1]["force"] is None
            assert row["width"] == pytest.approx(100 * row["force"] / snap["scale"], abs=0.1)
            assert snap["scale"] == 2 and snap["hover"] == "contact"
            forces.add(round(row["force"], 3))
            page.wait_for_timeout(150)
        assert len(forces) >= 2, f"the force bar did not move: {forces}"

        # The heat map: hot under region 3's centre, clear at region 7's (same face).
        far = LAYOUT.region(7).centre_mm
        points = [[u, v], [float(far[0]), float(far[1])]]
        heat = page.wait_for_function(HEAT_AT, arg=[u, v, points], timeout=15_000).json_value()
        assert (heat["w"], heat["h"]) == (NU, NV) and heat["ect"]["drawn"] > 0
        under, away = heat["px"]
        # opaque and red under the finger (alpha grows with the value: at least a third of the
        # colour scale there, which holds the largest recent value), clear far from it
        assert under["a"] > 100 and under["r"] > 200 and under["b"] < 100, heat
        assert away["a"] < 10, heat
        assert "ECT peak front" in page.text_content("#ect-peak")

        # Hovering over region 14: no finger, the indicator says so, its bar shows p_hover.
        snap = page.wait_for_function(
            f"() => {{ const s = ({SNAPSHOT})(); return s.hover === 'hover' ? s : null; }}",
            timeout=15_000,
        ).json_value()
        assert snap["count"] == "0" and snap["dots"] == []
        assert snap["p_hover"] == pytest.approx(0.9) and snap["hover_width"] == pytest.approx(
            90
        )
        assert "hovering" in page.text_content("#hover-indicator")

        # Two fingers on the back, at regions 10 and 18, each with its own force bar.
        snap = page.wait_for_function(
            f"() => {{ const s = ({SNAPSHOT})(); return s.count === '2' ? s : null; }}",
            timeout=15_000,
        ).json_value()
        got = sorted((d["k"], d["face"], d["cx"], -d["cy"]) for d in snap["dots"])
        want = [(k, *_centre(r)) for k, r in enumerate(PAIR)]
        assert [g[:2] for g in got] == [w[:2] for w in want]
        for g, w in zip(got, want):
            assert g[2:] == (pytest.approx(w[2], abs=0.01), pytest.approx(w[3], abs=0.01))
        assert [r["force"] for r in snap["rows"]] == [
            pytest.approx(0.8, abs=0.01),
            pytest.approx(1.2, abs=0.01),
        ]
        page.screenshot(path=str(SCREENSHOT), full_page=True)
    assert not errors, f"errors in the page: {errors}"
    assert engine.stats["errors"] == 0 and math.isfinite(engine.stats["latency_ms_p50"])
