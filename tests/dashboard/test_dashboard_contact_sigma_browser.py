"""In headless Chromium: the Contact panel shows each finger's force with its σ.

The frames are the live engine's own messages (``Output.to_json_dict()`` of a
``ContactReading``), published straight into the dashboard's hub, so the page sees exactly the
fields the engine sends: ``force_sigma_n`` per finger (N; ``null`` from a model that gives none).
An older engine's message has no ``force_sigma_n`` key at all; it must render as before (force
alone, no band, no error in the page).

What it catches: a σ not shown (text or band), a band that is not force ± 1σ on the bar's
scale, a band or "±" left over from the previous frame or shown for a finger without σ, and a
page that breaks (or prints "NaN") on a message without the field.

Needs Chromium and Playwright (the ``chromium`` fixture of ``conftest.py``).
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin.dashboard import DashboardServer, Hub
from ectskin.layout import default_layout
from ectskin.learn.predict import ContactReading, FingerEstimate
from ectskin.live.output import Output

pytestmark = pytest.mark.browser

LAYOUT = default_layout()
EXTENT = {"front": [[-20.0, 20.0], [5.0, 115.0]], "back": [[-20.0, 20.0], [5.0, 115.0]]}


class ContactEngine:
    """What the hub asks of an engine: counters, a reference re-capture and its meta (a
    contact head, no ECT image)."""

    stats: dict = {}

    def capture_reference(self) -> None:
        pass

    def meta(self) -> dict:
        return {
            "contact_model": True,
            "contact": {"faces": ["front", "back"], "face_extent": EXTENT, "window": 1},
            "ect": None,
        }


def _message(seq: int, fingers: tuple[FingerEstimate, ...], *, old: bool = False) -> dict:
    out = Output(
        seq=seq,
        t=seq / 30,
        raw=np.ones(LAYOUT.n_pairs),
        contact=ContactReading(len(fingers), 0.97, 0.01, fingers),
    )
    msg = out.to_json_dict()
    if old:  # an engine of before the force's σ: no such key
        for f in msg["contact"]["fingers"]:
            del f["force_sigma_n"]
    return msg


ROWS = """() => [...document.querySelectorAll('#contact-fingers .cf-row')].map(r => {
  const band = r.querySelector('.fsig');
  return { force: r.dataset.force, sigma: r.dataset.sigma, text: r.querySelector('.v').textContent,
           bar: parseFloat(r.querySelector('.bar').style.width),
           band: band.hidden ? null : { left: parseFloat(band.style.left),
                                        width: parseFloat(band.style.width),
                                        shown: band.getBoundingClientRect().width > 0 } };
})"""


def _rows_when(page, seq: int) -> list[dict]:
    page.wait_for_function(
        f"() => document.getElementById('frame-seq').textContent === '{seq}'", timeout=10_000
    )
    return page.evaluate(ROWS)


def test_force_sigma_shown_and_older_messages_still_render(chromium):
    hub = Hub(LAYOUT, ContactEngine())
    errors: list[str] = []
    with DashboardServer(None, hub=hub, port=0) as server:
        page = chromium.new_page(viewport={"width": 1400, "height": 1400})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        hub.set_engine_state("running")
        page.goto(server.url)
        page.wait_for_selector('#connection-status[data-state="waiting"]', timeout=10_000)
        assert page.locator("#contact-panel").is_visible()
        assert "force ± 1 σ" in page.text_content("#contact-panel .legend")

        # finger 1: 1.0 ± 0.2 N; finger 2: 0.8 N from a model without σ (null in the message)
        hub.publish(
            _message(
                1,
                (
                    FingerEstimate("front", 0.0, 60.0, 2.0, 1.0, 0.2),
                    FingerEstimate("back", 5.0, 40.0, 3.0, 0.8, None),
                ),
            )
        )
        one, two = _rows_when(page, 1)
        assert one["text"] == "1.00 ± 0.20 N" and one["sigma"] == "0.2"
        # the scale's full bar is 2 N: the bar to 50 %, the band over 0.8..1.2 N = 40..60 %
        assert one["bar"] == pytest.approx(50.0)
        assert one["band"] == {
            "left": pytest.approx(40.0),
            "width": pytest.approx(20.0),
            "shown": True,
        }
        assert two["text"] == "0.80 N" and two["sigma"] == "" and two["band"] is None

        # a σ that reaches below 0 N: the band starts at the bar's start
        hub.publish(_message(2, (FingerEstimate("front", 0.0, 60.0, 2.0, 0.3, 0.5),)))
        one, two = _rows_when(page, 2)
        assert one["text"] == "0.30 ± 0.50 N"
        assert one["band"]["left"] == pytest.approx(0.0)
        assert one["band"]["width"] == pytest.approx(40.0)  # 0..0.8 N
        assert two["band"] is None and two["force"] == ""

        # an older engine's message: no force_sigma_n key at all
        hub.publish(
            _message(
                3,
                (
                    FingerEstimate("front", 0.0, 60.0, 2.0, 1.4, 0.2),
                    FingerEstimate("back", 5.0, 40.0, 3.0, 0.6, 0.1),
                ),
                old=True,
            )
        )
        one, two = _rows_when(page, 3)
        assert (one["text"], two["text"]) == ("1.40 N", "0.60 N")
        assert one["band"] is None and two["band"] is None
        assert one["sigma"] == two["sigma"] == ""
        assert one["bar"] == pytest.approx(70.0) and two["bar"] == pytest.approx(30.0)
        assert "NaN" not in page.text_content("#contact-panel")
    assert not errors, f"errors in the page: {errors}"
