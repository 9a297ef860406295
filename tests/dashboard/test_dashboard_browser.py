"""End to end in headless Chromium: replayed HDF5 recording → LiveEngine → dashboard → page.

The recording is synthetic and small: a rest trial (the reference), then touches on a few
regions, each with its own pattern of readout changes and a bend of the markers that grows with
the force. The predictors are stand-ins with the ``ectskin.learn.predict`` protocol that know the
recording's patterns (the learning is tested elsewhere; here the page is under test). The touch
stand-in confuses each touched region with a neighbour, so the page must light that neighbour (the
prediction) while it outlines the touched region (the label), and the markers must move.

Needs Chromium and Playwright (the ``chromium`` fixture of ``conftest.py``: skipped without them
outside CI, failed in CI).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from ectskin.dashboard import DashboardServer
from ectskin.io.hdf5 import RecordingWriter
from ectskin.layout import default_layout
from ectskin.live import LiveEngine, open_source

pytestmark = pytest.mark.browser

LAYOUT = default_layout()
RATE_HZ = 30.0
TOUCHED = (2, 14, 7, 11)  # two front, two back regions
# The stand-in touch model confuses each touched region with a neighbour (the paper's errors are
# all between adjacent regions): the page must light the prediction, not the label.
CONFUSED = {2: 3, 3: 2, 14: 15, 15: 14, 7: 8, 8: 7, 11: 12, 12: 11}
FRAMES_PER_TRIAL = 45
GAIN = 0.15  # calibrated change per unit force along a region's pattern
BEND_MM = 12.0  # tip displacement at force 1
REST = np.array([[25.0, 0.0, z] for z in (24.0, 48.0, 72.0, 96.0, 120.0)])
SCREENSHOT = Path("/tmp/dashboard.png")


def _patterns() -> np.ndarray:
    """(n_classes, n_pairs) unit patterns; region r moves mostly pairs on its own face."""
    rng = np.random.default_rng(7)
    pats = np.zeros((LAYOUT.n_classes, LAYOUT.n_pairs))
    surf = {r.id: r.surface for r in LAYOUT.regions}
    pair_surf = [(LAYOUT.electrode_surface(i), LAYOUT.electrode_surface(j)) for i, j in LAYOUT.pairs]
    for r in range(1, LAYOUT.n_classes):
        w = np.array([2.0 if surf[r] in ps else 0.3 for ps in pair_surf])
        p = w * rng.uniform(0.2, 1.0, LAYOUT.n_pairs)
        pats[r] = p / np.linalg.norm(p)
    return pats


PATTERNS = _patterns()


def _bend(force: float, side: float) -> np.ndarray:
    """(n_markers, 3) displacement: y grows with (z / L)^2 (a clamped beam's shape)."""
    d = np.zeros_like(REST)
    d[:, 1] = -side * BEND_MM * force * (REST[:, 2] / 120.0) ** 2
    return d


def _side(region: int) -> float:
    return 1.0 if LAYOUT.region(region).surface == "front" else -1.0


def write_patterned_recording(path: Path) -> Path:
    """Write the synthetic recording with the crash-safe writer (as ``ectskin record`` does)."""
    rng = np.random.default_rng(0)
    base = 1.0 + rng.uniform(0.0, 1.0, LAYOUT.n_pairs)  # pF
    t = np.arange(FRAMES_PER_TRIAL) / RATE_HZ

    def noise() -> np.ndarray:
        return rng.normal(0.0, 1e-4, (FRAMES_PER_TRIAL, LAYOUT.n_pairs))

    with RecordingWriter(path, LAYOUT, RATE_HZ) as w:
        w.start_trial("rest", inflation=(0, 0, 0), region=0)
        w.append(base * (1 + noise()), t, np.zeros(FRAMES_PER_TRIAL, dtype=int),
                 markers=np.repeat(REST[None], FRAMES_PER_TRIAL, 0))
        for r in TOUCHED:
            force = 0.6 + 0.4 * np.sin(np.pi * t / t[-1])  # N
            w.start_trial(f"touch-{r}", inflation=(0, 0, 0), region=r)
            w.append(base * (1 + GAIN * force[:, None] * PATTERNS[r] + noise()), t,
                     np.full(FRAMES_PER_TRIAL, r), markers=np.stack(
                         [REST + _bend(f, _side(r)) for f in force]), force=force)
    return path


class TemplateTouch:
    """``TouchPredictor`` stand-in: softmax over the cosine of c with each region's pattern,
    then regions swapped as in ``CONFUSED``."""

    n_pairs = LAYOUT.n_pairs
    n_classes = LAYOUT.n_classes

    def predict(self, c: np.ndarray) -> np.ndarray:
        norm = float(np.linalg.norm(c))
        score = np.zeros(self.n_classes)
        if norm < 0.02:  # no touch
            score[0] = 10.0
        else:
            score[1:] = 10.0 * (PATTERNS[1:] @ c) / norm
        e = np.exp(score - score.max())
        probs = e / e.sum()
        perm = [CONFUSED.get(k, k) for k in range(self.n_classes)]
        out = np.empty_like(probs)
        out[perm] = probs
        return out


class TemplateTrack:
    """``TrackPredictor`` stand-in: force and face from the best-matching pattern, then bend."""

    n_pairs = LAYOUT.n_pairs
    n_markers = LAYOUT.n_markers
    window = 10

    def predict(self, window: np.ndarray, init: np.ndarray) -> np.ndarray:
        c = window.mean(axis=0)
        proj = PATTERNS[1:] @ c
        k = int(np.argmax(proj)) + 1
        force = max(float(proj[k - 1]), 0.0) / GAIN
        return init + _bend(force, _side(k))


def test_page_follows_a_replayed_recording(tmp_path, chromium):
    rec = write_patterned_recording(tmp_path / "synthetic.h5")
    source = open_source(f"replay:{rec}", speed=2.0, loop=True)
    engine = LiveEngine(source, touch=TemplateTouch(), track=TemplateTrack(), reference_frames=30)
    errors: list[str] = []
    with DashboardServer(engine, port=0) as server:
        page = chromium.new_page(viewport={"width": 1400, "height": 1000})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(server.url)
        page.wait_for_selector('#connection-status[data-state="open"]', timeout=10_000)
        assert page.locator("#faces .region").count() == 18
        assert page.locator("#probs .prob-row").count() == 19
        # the page tells the newcomer how the reference must be taken
        assert "untouched and uninflated" in page.text_content("#reference-hint")

        # The reference: captured from the rest trial's first 30 frames, shown with its frames.
        page.wait_for_selector('#reference-detail[data-frames="0..29"]', timeout=15_000)
        assert "from frames 0..29" in page.text_content("#reference-detail")
        assert page.locator("#reference-warning").is_hidden()

        # Regions light up, and the lit region changes as the replay moves on.
        page.wait_for_selector("#faces .region.lit", timeout=15_000)
        snapshot = """() => ({
            lit: [...document.querySelectorAll('#faces .region.lit')]
                   .map(e => Number(e.dataset.region)),
            truth: [...document.querySelectorAll('#faces .region.truth')]
                   .map(e => Number(e.dataset.region)),
            cls: document.getElementById('predicted-class').textContent,
            top: [...document.querySelectorAll('#probs .prob-row.top')]
                   .map(e => Number(e.dataset.class)),
        })"""
        lit, pairs = set(), set()
        deadline = time.monotonic() + 15
        while len(lit) < 2 and time.monotonic() < deadline:
            snap = page.evaluate(snapshot)
            assert len(snap["lit"]) <= 1 and len(snap["truth"]) <= 1, snap
            if snap["lit"]:
                (r,) = snap["lit"]
                assert snap["cls"] == str(r) and snap["top"] == [r], snap
                lit.add(r)
                if snap["truth"]:
                    pairs.add((snap["truth"][0], r))
            time.sleep(0.05)
        assert len(lit) >= 2, f"only region(s) {lit} lit"
        predicted = {CONFUSED[r] for r in TOUCHED}
        assert lit <= predicted, f"lit {lit}: the model predicts only {predicted}"
        assert pairs and all(CONFUSED[t] == r for t, r in pairs), pairs

        # Markers move: the page's max displacement from the reference pose is > 0.5 mm
        # (the recording bends the tip by 7-12 mm during touches).
        page.wait_for_function(
            "() => parseFloat(document.getElementById('markers-moved').dataset.value) > 0.5",
            timeout=15_000,
        )
        moved = float(page.get_attribute("#markers-moved", "data-value"))
        assert 0.5 < moved < 1.5 * BEND_MM
        assert page.get_attribute("#markers-moved", "data-source") == "pred"
        assert page.locator('#markers-yz circle[data-kind="pred"][visibility="visible"]').count() == 5

        # Marker errors are drawn on their own scale, with a legend (sub-mm errors were
        # invisible on the 140-mm views, and nothing said what red, blue and "moved" were).
        assert page.locator("#marker-errors .mk-row").count() == 5
        page.wait_for_function(
            "() => [...document.querySelectorAll('#marker-errors .mk-row')]"
            ".some(r => parseFloat(r.dataset.moved) > 0.5 && r.dataset.error !== '')",
            timeout=15_000,
        )
        bars = page.evaluate("""() => {
            const scale = parseFloat(
                document.getElementById('marker-scale').dataset.scaleError);
            return [...document.querySelectorAll('#marker-errors .mk-row')].map(r => ({
                scale, moved: parseFloat(r.dataset.moved), error: parseFloat(r.dataset.error),
                width: parseFloat(r.querySelector('.bar.err').style.width) }));
        }""")
        for b in bars:
            if math.isfinite(b["error"]):
                assert b["width"] == pytest.approx(100 * b["error"] / b["scale"], abs=0.1)
        mm = [b["error"] for b in bars if math.isfinite(b["error"])]
        assert mm and bars[0]["scale"] <= max(0.5, 2.5 * max(mm))  # magnified
        legend = page.text_content("#markers-panel .legend")
        for words in ("reference pose", "estimated (model)", "true (motion capture)"):
            assert words in legend
        assert "moved from the reference pose" in page.text_content("#marker-errors")

        # Replay shows the trial and its inflation, and the chart marks trial boundaries.
        page.wait_for_function(
            "() => window.ectskinDashboard.state.chartBoundaries.length > 0", timeout=15_000
        )
        assert page.text_content("#trial-info").startswith("trial ")
        assert "uninflated 0/0/0 ml" in page.text_content("#trial-info")
        boundaries = page.evaluate("() => window.ectskinDashboard.state.chartBoundaries")
        assert set(boundaries) <= {"rest"} | {f"touch-{r}" for r in TOUCHED}

        # The strip chart has a time axis and never stretches noise to full height: every
        # pair's vertical span is at least 20 fF (the rest trial's noise is ~0.15 fF).
        ticks = page.get_attribute("#strip-chart", "data-ticks").split(",")
        assert ticks == ["-10 s", "-5 s", "now"]
        spans = page.evaluate("() => window.ectskinDashboard.state.chartSpans")
        assert len(spans) == LAYOUT.n_pairs and min(spans) >= 0.02
        flicker = page.evaluate("() => window.ectskinDashboard.chartRange(1.0, 1.001, false)")
        assert flicker["span"] == pytest.approx(0.02)  # 1 fF is 5 % of the height, not 100 %

        # Counters come from the engine and grow.
        n1 = int(page.text_content("#frames-count"))
        page.wait_for_function(
            f"() => parseInt(document.getElementById('frames-count').textContent) > {n1}",
            timeout=5_000,
        )
        assert page.text_content("#policy") == "skip-to-newest"
        assert float(page.text_content("#latency-p50")) > 0

        # The strip chart is drawn: bluish pixels (front-front traces, #2f6fdb) appear.
        page.screenshot(path=str(SCREENSHOT), full_page=True)
        drawn = page.evaluate("""() => {
            const c = document.getElementById('strip-chart');
            const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
            let n = 0;
            for (let i = 0; i < d.length; i += 4)
              if (d[i + 3] > 100 && d[i + 2] - d[i] > 80) n++;
            return n; }""")
        assert drawn > 300, f"{drawn} trace pixels"

        # The button asks the engine for a new reference.
        with page.expect_response("**/api/reference") as resp_info:
            page.click("#capture-reference")
        resp = resp_info.value
        assert resp.status == 200 and resp.json()["ok"] is True
        page.wait_for_selector(
            '#reference-status:is([data-state="requested"], [data-state="capturing"], '
            '[data-state="ready"])', timeout=5_000)
        stats = json.loads(page.evaluate("() => fetch('/api/stats').then(r => r.text())"))
        assert stats["dashboard"]["reference_requests"] == 1
        page.wait_for_selector('#reference-status[data-state="ready"]', timeout=20_000)

        # The badge: "live" only while frames keep coming.
        states = page.evaluate("""() => {
            const b = window.ectskinDashboard.badge;
            return [b(true, 'running', 100), b(true, 'running', 5000), b(true, 'ended', 100),
                    b(true, 'error', 100), b(false, 'running', 100), b(true, 'running', null)]
                   .map(x => x[0]); }""")
        assert states == ["open", "stale", "ended", "error", "closed", "waiting"]

        # The source ends: the badge no longer says "live".
        engine.stop()
        page.wait_for_selector('#connection-status[data-state="ended"]', timeout=10_000)
        assert "ended" in page.text_content("#connection-status")
    assert not errors, f"errors in the page: {errors}"
    assert engine.stats["processed"] > 0 and math.isfinite(engine.stats["latency_ms_p50"])
