"""In headless Chromium: the Contact panel draws the physical inversion beside the contact model.

The frames are the live engine's own messages (``Output.to_json_dict()`` with an
``InversionFrame`` of :class:`ectskin.inversion.fit.FingerEstimate`), published straight into the
dashboard's hub, so the page sees exactly what the engine sends: per finger its face, pressing or
hovering, u, v, force, height and their standard errors, ``null`` where an SE is not finite.

The expected drawing is worked out here, not read back from the page's code: the face's viewBox
from the layout's skins and the meta's extents (plus the page's 4 mm margin), the map's scale
(px per mm) from the SVG's rendered box and that viewBox (``preserveAspectRatio`` "meet": the
smaller ratio, the drawing centred), and from them where (u, v) lands on the screen and how many
pixels an SE of s mm spans (2 s × scale across the ellipse).

What each check catches:
* ellipse ``rx``/``ry`` equal to ``u_se_mm``/``v_se_mm`` with u_se ≠ v_se, and its rendered box
  2·SE·scale wide and high: the two SEs swapped, an SE drawn in pixels or scaled twice (the
  scale forgotten or applied again), a diameter drawn for a radius;
* the viewBox equal to the expected one: a face extent of the inversion left out of the drawing;
* the diamond's rendered centre at the fitted (u, v): a marker drawn at u + SE, at v instead of
  −v (upside down), or on the wrong face;
* the hovering finger hollow, the pressing one filled: a mode not shown;
* a finger whose u SE is null is neither drawn nor left drawn from the frame before, and its row
  says so: drawing with a null SE (an ellipse of NaN or 0 radius passed off as certain);
* a message with ``inversion: null``, and one without the key (an older engine), clear the
  drawing and say why: a stale fit left on screen, a page that breaks on the missing key;
* the learned model's dot still where it was: the inversion drawn instead of it, not beside it;
* with ``--inversion-every 3`` the fit stands for its own frame and the two after it, not longer.

Needs Chromium and Playwright (the ``chromium`` fixture of ``conftest.py``).
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest

from ectskin.dashboard import DashboardServer, Hub
from ectskin.inversion.fit import FingerEstimate as Fitted
from ectskin.layout import default_layout
from ectskin.learn.predict import ContactReading, FingerEstimate
from ectskin.live.output import InversionFrame, Output

pytestmark = pytest.mark.browser

LAYOUT = default_layout()
CONTACT_EXTENT = {"front": [[-20.0, 20.0], [5.0, 115.0]], "back": [[-20.0, 20.0], [5.0, 115.0]]}
# the inversion's field reaches past the skins on the front: the drawing must cover it
INVERSION_EXTENT = {"front": [[-24.0, 24.0], [0.0, 120.0]], "back": [[-20.0, 20.0], [5.0, 115.0]]}
MARGIN_MM = 4.0  # the page's margin around a face's extent (app.js buildContact)


class Engine:
    """What the hub asks of an engine: counters, a reference re-capture and its meta."""

    stats: dict = {}

    def __init__(self, *, contact: bool = True, every: int = 1) -> None:
        self.contact, self.every = contact, every

    def capture_reference(self) -> None:
        pass

    def meta(self) -> dict:
        contact = {"faces": ["front", "back"], "face_extent": CONTACT_EXTENT, "window": 1}
        return {
            "contact_model": self.contact,
            "contact": contact if self.contact else None,
            "ect": None,
            "inversion": {
                "states": [[0.0, 0.0, 0.0]],
                "faces": ["back", "front"],
                "face_extent": INVERSION_EXTENT,
                "every": self.every,
                "readout": "absolute",
                "max_fingers": 2,
                "warm": True,
            },
        }


def fitted(face, u, v, u_se, v_se, *, force=(0.0, 0.0), height=None) -> Fitted:
    """A fitted finger: pressing with ``force`` (value, SE) N, or hovering at ``height`` mm."""
    if height is None:
        return Fitted(face, True, u, v, force[0], 0.0, u_se, v_se, force[1], 0.0)
    return Fitted(face, False, u, v, 0.0, height[0], u_se, v_se, 0.0, height[1])


def message(seq, fingers=None, *, converged=True, warm=True, fit_ms=0.7, drop_key=False) -> dict:
    """The frame message of an engine whose contact model sees one finger at front (0, 60) and
    whose inversion found ``fingers`` (None: no inversion on this frame)."""
    inv = None
    if fingers is not None:
        inv = InversionFrame(
            state=(0.0, 0.0, 0.0),
            n_fingers=len(fingers),
            fingers=tuple(fingers),
            bic_by_count=(900.0, 40.0, math.inf),
            converged=converged,
            warm=warm,
            fit_ms=fit_ms,
        )
    out = Output(
        seq=seq,
        t=seq / 30,
        raw=np.ones(LAYOUT.n_pairs),
        contact=ContactReading(1, 0.97, 0.01, (FingerEstimate("front", 0.0, 60.0, 2.0, 1.0),)),
        inversion=inv,
    )
    msg = out.to_json_dict()
    if drop_key:  # an engine from before the inversion: no such key
        del msg["inversion"]
    return msg


def expected_viewbox(face: str, *, contact: bool = True) -> list[float]:
    """The face's viewBox [x, y, w, h]: the union of its skins and the meta's extents, 4 mm
    around, y = -v."""
    us, vs = [], []
    for s in LAYOUT.to_dict()["skins"]:
        if s["surface"] == face:
            us += s["u_mm"]
            vs += s["v_mm"]
    for ext in [INVERSION_EXTENT[face]] + ([CONTACT_EXTENT[face]] if contact else []):
        us += ext[0]
        vs += ext[1]
    u0, u1, v0, v1 = min(us), max(us), min(vs), max(vs)
    m = MARGIN_MM
    return [u0 - m, -(v1 + m), u1 - u0 + 2 * m, v1 - v0 + 2 * m]


def screen(face: dict, u: float, v: float) -> tuple[float, float, float]:
    """(x, y) px on the page of the point (u, v) mm of a face, and the scale px/mm: the
    viewBox fitted into the SVG's box, aspect kept, centred."""
    x, y, w, h = face["expected_vb"]
    box = face["box"]
    scale = min(box["w"] / w, box["h"] / h)
    left = box["x"] + (box["w"] - w * scale) / 2
    top = box["y"] + (box["h"] - h * scale) / 2
    return left + (u - x) * scale, top + (-v - y) * scale, scale


SNAPSHOT = """() => {
  const rect = (el) => { const r = el.getBoundingClientRect();
                         return { x: r.x, y: r.y, w: r.width, h: r.height }; };
  const faces = {};
  for (const svg of document.querySelectorAll('#contact-faces svg')) {
    const vb = svg.viewBox.baseVal;
    const item = { box: rect(svg), vb: [vb.x, vb.y, vb.width, vb.height], ell: {}, mark: {} };
    for (const e of svg.querySelectorAll('.inv-se[visibility="visible"]')) {
      item.ell[e.dataset.finger] = { rx: e.getAttribute('rx'), ry: e.getAttribute('ry'),
        cx: e.getAttribute('cx'), cy: e.getAttribute('cy'), box: rect(e),
        hovering: e.classList.contains('hovering') };
    }
    for (const m of svg.querySelectorAll('.inv-mark[visibility="visible"]')) {
      const cs = getComputedStyle(m);
      item.mark[m.dataset.finger] = { box: rect(m), fill: cs.fill, stroke: cs.stroke,
        hovering: m.classList.contains('hovering') };
    }
    item.dots = [...svg.querySelectorAll('.finger-dot[visibility="visible"]')].map(d =>
      [Number(d.getAttribute('cx')), Number(d.getAttribute('cy'))]);
    faces[svg.closest('.cface').dataset.face] = item;
  }
  const rows = [...document.querySelectorAll('#inv-fingers .inv-row')].map(r => ({
    face: r.dataset.face, mode: r.dataset.mode, drawn: r.dataset.drawn,
    absent: r.classList.contains('absent'),
    where: r.querySelector('.where').textContent, what: r.querySelector('.what').textContent }));
  const fit = document.getElementById('inv-fit');
  const note = document.getElementById('inv-note');
  return { faces, rows, count: document.getElementById('inv-count').textContent,
           fit: fit.textContent, fit_warn: fit.classList.contains('warn'),
           note: note.textContent, note_state: note.dataset.state,
           panel: !document.getElementById('inversion').hidden,
           text: document.getElementById('contact-panel').textContent };
}"""


def snapshot(page, seq: int, *, contact: bool = True) -> dict:
    """The panel once frame ``seq`` is shown, each face with its expected viewBox."""
    page.wait_for_function(
        f"() => document.getElementById('frame-seq').textContent === '{seq}'", timeout=10_000
    )
    snap = page.evaluate(SNAPSHOT)
    for face, item in snap["faces"].items():
        item["expected_vb"] = expected_viewbox(face, contact=contact)
        assert item["vb"] == pytest.approx(item["expected_vb"]), face
    assert "NaN" not in snap["text"] and "undefined" not in snap["text"]
    return snap


def assert_finger(face: dict, k: int, u: float, v: float, u_se: float, v_se: float) -> None:
    """Finger ``k`` drawn on ``face``: its ellipse of semi-axes u_se × v_se mm (attributes, and
    on the screen 2 SE × the map's scale) centred on (u, v), its diamond centred there too."""
    x, y, scale = screen(face, u, v)
    ell, mark = face["ell"][str(k)], face["mark"][str(k)]
    assert (float(ell["rx"]), float(ell["ry"])) == (pytest.approx(u_se), pytest.approx(v_se))
    assert (float(ell["cx"]), float(ell["cy"])) == (pytest.approx(u), pytest.approx(-v))
    b = ell["box"]
    assert b["w"] == pytest.approx(2 * u_se * scale, abs=0.5)
    assert b["h"] == pytest.approx(2 * v_se * scale, abs=0.5)
    assert b["x"] + b["w"] / 2 == pytest.approx(x, abs=0.5)
    assert b["y"] + b["h"] / 2 == pytest.approx(y, abs=0.5)
    m = mark["box"]  # the marker sits at the fitted point itself, whatever its SE
    assert m["x"] + m["w"] / 2 == pytest.approx(x, abs=0.5)
    assert m["y"] + m["h"] / 2 == pytest.approx(y, abs=0.5)


def open_page(chromium, server, errors: list[str]):
    page = chromium.new_page(viewport={"width": 1400, "height": 1600})
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(server.url)
    page.wait_for_selector('#connection-status[data-state="waiting"]', timeout=10_000)
    return page


@contextlib.contextmanager
def running_page(chromium, engine):
    """(hub, page): the dashboard of ``engine`` running, its page open; no error in the page by
    the end."""
    hub = Hub(LAYOUT, engine)
    errors: list[str] = []
    with DashboardServer(None, hub=hub, port=0) as server:
        hub.set_engine_state("running")
        page = open_page(chromium, server, errors)
        assert page.locator("#contact-panel").is_visible()
        yield hub, page
    assert not errors, f"errors in the page: {errors}"


def test_inversion_fingers_drawn_with_their_standard_errors(chromium):
    with running_page(chromium, Engine()) as (hub, page):
        assert page.locator("#inversion").is_visible()
        legend = page.text_content("#contact-panel .legend")
        assert "inversion (filled: pressing, hollow: hovering)" in legend
        assert "inversion ± 1 SE (u × v)" in legend

        # One finger pressing on the front: u 3 ± 2 mm, v 45 ± 5 mm, 0.84 ± 0.05 N.
        hub.publish(message(1, [fitted("front", 3.0, 45.0, 2.0, 5.0, force=(0.84, 0.05))]))
        s = snapshot(page, 1)
        front, back = s["faces"]["front"], s["faces"]["back"]
        assert list(front["ell"]) == ["0"] and list(front["mark"]) == ["0"]
        assert back["ell"] == {} and back["mark"] == {}
        assert_finger(front, 0, 3.0, 45.0, 2.0, 5.0)
        # pressing: filled with finger 1's colour (#0b8a7a)
        assert front["mark"]["0"]["fill"] == "rgb(11, 138, 122)"
        assert not front["mark"]["0"]["hovering"] and not front["ell"]["0"]["hovering"]
        assert front["dots"] == [[0.0, -60.0]]  # the contact model's finger, beside it
        assert s["count"] == "1"
        assert s["fit"] == "converged, warm start, fit 0.70 ms" and not s["fit_warn"]
        one, two = s["rows"]
        assert one == {
            "face": "front",
            "mode": "pressing",
            "drawn": "1",
            "absent": False,
            "where": "front u 3.0 ± 2.0, v 45.0 ± 5.0 mm",
            "what": "pressing 0.840 ± 0.050 N",
        }
        assert two["absent"] and two["where"] == two["what"] == ""
        assert s["note"] == "" and s["note_state"] == "drawn"

        # Two fingers: one pressing on the front, one hovering 6 ± 2 mm above the back.
        hub.publish(
            message(
                2,
                [
                    fitted("front", -5.0, 80.0, 0.5, 1.5, force=(1.2, 0.1)),
                    fitted("back", 4.0, 30.0, 3.0, 1.0, height=(6.0, 2.0)),
                ],
                converged=False,
                warm=False,
                fit_ms=1.93,
            )
        )
        s = snapshot(page, 2)
        front, back = s["faces"]["front"], s["faces"]["back"]
        assert list(front["ell"]) == ["0"] and list(back["ell"]) == ["1"]
        assert list(front["mark"]) == ["0"] and list(back["mark"]) == ["1"]
        assert_finger(front, 0, -5.0, 80.0, 0.5, 1.5)
        assert_finger(back, 1, 4.0, 30.0, 3.0, 1.0)
        # hovering: a hollow diamond (white inside, outlined in finger 2's #3f6fb0), its
        # ellipse marked so
        assert back["mark"]["1"]["fill"] == "rgb(255, 255, 255)"
        assert back["mark"]["1"]["stroke"] == "rgb(63, 111, 176)" and back["ell"]["1"]["hovering"]
        assert front["mark"]["0"]["fill"] == "rgb(11, 138, 122)"
        assert s["count"] == "2"
        assert s["fit"] == "NOT converged, cold start, fit 1.93 ms" and s["fit_warn"]
        one, two = s["rows"]
        assert (one["where"], one["what"]) == (
            "front u -5.00 ± 0.50, v 80.0 ± 1.5 mm",
            "pressing 1.20 ± 0.10 N",
        )
        assert (two["face"], two["mode"], two["drawn"]) == ("back", "hovering", "1")
        assert (two["where"], two["what"]) == (
            "back u 4.0 ± 3.0, v 30.0 ± 1.0 mm",
            "hovering 6.0 ± 2.0 mm above",
        )

        # A finger whose u is unresolved (SE inf: null in the message) is not drawn, and the
        # frame before's drawing of that slot is gone; a force SE that is not finite is said so.
        msg = message(
            3,
            [
                fitted("front", 2.0, 50.0, math.inf, 1.0, force=(0.9, 0.1)),
                fitted("front", -8.0, 90.0, 1.0, 2.0, force=(0.5, math.inf)),
            ],
        )
        assert msg["inversion"]["fingers"][0]["u_se_mm"] is None
        assert msg["inversion"]["fingers"][1]["force_se_n"] is None
        hub.publish(msg)
        s = snapshot(page, 3)
        front, back = s["faces"]["front"], s["faces"]["back"]
        assert list(front["ell"]) == ["1"] and list(front["mark"]) == ["1"]
        assert back["ell"] == {} and back["mark"] == {}
        assert_finger(front, 1, -8.0, 90.0, 1.0, 2.0)
        one, two = s["rows"]
        assert one["drawn"] == "" and one["where"] == (
            "front: point not resolved (SE not finite), not drawn"
        )
        assert two["what"] == "pressing 0.50 ± — (SE not finite) N"
        assert s["note"] == "1 finger(s) with a point not resolved: not drawn"

        # No finger (the count BIC chose is 0): the fit is reported, nothing is drawn.
        hub.publish(message(4, [], converged=True, warm=False, fit_ms=0.31))
        s = snapshot(page, 4)
        assert all(f["ell"] == {} and f["mark"] == {} for f in s["faces"].values())
        assert s["count"] == "0" and s["fit"] == "converged, cold start, fit 0.31 ms"
        assert all(r["absent"] and r["where"] == r["what"] == "" for r in s["rows"])
        assert s["note"] == "" and s["note_state"] == "drawn"

        # No inversion on this frame (before the reference): nothing drawn, and it says so.
        hub.publish(message(5, None))
        s = snapshot(page, 5)
        assert all(f["ell"] == {} and f["mark"] == {} for f in s["faces"].values())
        assert s["count"] == "—" and s["fit"] == "" and s["note_state"] == "none"
        assert s["note"] == "no inversion for this frame (no reference yet)"
        assert all(r["absent"] and r["where"] == "" for r in s["rows"])

        # A fit again, then an older engine's message (no key): cleared again, and it says why.
        hub.publish(message(6, [fitted("back", 1.0, 20.0, 0.8, 0.4, force=(0.3, 0.02))]))
        s = snapshot(page, 6)
        assert_finger(s["faces"]["back"], 0, 1.0, 20.0, 0.8, 0.4)
        hub.publish(message(7, [fitted("back", 1.0, 20.0, 0.8, 0.4)], drop_key=True))
        s = snapshot(page, 7)
        assert all(f["ell"] == {} and f["mark"] == {} for f in s["faces"].values())
        assert s["note"] == "this engine sends no inversion (a version from before it)"
        assert s["faces"]["front"]["dots"] == [[0.0, -60.0]]  # the contact model goes on


def test_inversion_alone_and_held_between_fits(chromium):
    """An engine with the inversion only (no contact model) fitting every 3rd frame."""
    with running_page(chromium, Engine(contact=False, every=3)) as (hub, page):
        assert "inversion every 3 frame(s)" in page.text_content("#contact-note")

        hub.publish(message(10, [fitted("front", 6.0, 70.0, 1.5, 0.7, force=(0.6, 0.04))]))
        s = snapshot(page, 10, contact=False)
        assert_finger(s["faces"]["front"], 0, 6.0, 70.0, 1.5, 0.7)
        for seq in (11, 12):  # the frames the fit of frame 10 stands for
            hub.publish(message(seq, None))
            s = snapshot(page, seq, contact=False)
            assert_finger(s["faces"]["front"], 0, 6.0, 70.0, 1.5, 0.7)
            assert s["note"] == "the fit of frame 10 (one every 3 frames)"
            assert s["note_state"] == "held"
        hub.publish(message(13, None))  # the next fit is due here: without one, none
        s = snapshot(page, 13, contact=False)
        assert all(f["ell"] == {} and f["mark"] == {} for f in s["faces"].values())
        assert (
            s["note"] == "no inversion for this frame (no reference yet, or a frame between fits)"
        )


def test_no_inversion_head_no_inversion_drawn(chromium):
    """An engine without the inversion (meta.inversion null): no section, no legend, a note."""

    class NoInversion(Engine):
        def meta(self) -> dict:
            return dict(super().meta(), inversion=None)

    with running_page(chromium, NoInversion()) as (hub, page):
        assert not page.locator("#inversion").is_visible()
        assert not page.locator("#contact-panel .inv-legend").first.is_visible()
        assert "no physical inversion (ectskin live --fields DIR)" in page.text_content(
            "#contact-note"
        )
        hub.publish(message(1, [fitted("front", 3.0, 45.0, 2.0, 5.0)]))
        page.wait_for_function(
            "() => document.getElementById('frame-seq').textContent === '1'", timeout=10_000
        )
        assert page.locator("#contact-faces .inv-se").count() == 0
        assert page.locator("#contact-faces .finger-dot[visibility=visible]").count() == 1


def test_a_fit_whose_frame_was_skipped_still_stands_for_the_frames_after_it(chromium):
    """The hub sends the newest frame only: a page that never got the frame carrying the fit
    (here: it connects after it) draws the fit from ``inversion_fit`` of the frames after it."""
    hub = Hub(LAYOUT, Engine(contact=False, every=3))
    errors: list[str] = []
    with DashboardServer(None, hub=hub, port=0) as server:
        hub.set_engine_state("running")
        hub.publish(message(10, [fitted("front", 6.0, 70.0, 1.5, 0.7, force=(0.6, 0.04))]))
        hub.publish(message(11, None))
        page = chromium.new_page(viewport={"width": 1400, "height": 1600})
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(server.url)  # the newest frame (11) is what it gets, not the fit's (10)
        s = snapshot(page, 11, contact=False)
        assert_finger(s["faces"]["front"], 0, 6.0, 70.0, 1.5, 0.7)
        assert s["note"] == "the fit of frame 10 (one every 3 frames)"
        hub.publish(message(13, None))  # beyond the frames the fit stands for: none
        s = snapshot(page, 13, contact=False)
        assert all(f["ell"] == {} and f["mark"] == {} for f in s["faces"].values())
    assert not errors, f"errors in the page: {errors}"
