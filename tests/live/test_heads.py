"""The live engine's contact and ECT image heads: what they are fed (window, reference, channels,
period), what they emit (Output and its JSON message), and the checks at the door.

The stand-ins record their inputs; the expected inputs are computed here by hand from the frames
(paper Eq. 2 against the mean of the reference frames, c − c_0 in pF for the imager).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.learn.predict import ContactReading, FingerEstimate
from ectskin.live import EctHead, LiveEngine, ReplaySource
from ectskin.live.output import ECT_LEVELS, quantise

LAYOUT = default_layout()
P, M = LAYOUT.n_pairs, LAYOUT.n_markers
EXTENT = {"front": [[-20.0, 20.0], [5.0, 115.0]], "back": [[-20.0, 20.0], [5.0, 115.0]]}


class FakeContact:
    """ContactPredictor protocol; remembers its windows; one finger on the front whose u is the
    window's mean input (so the reading shows what the model was fed)."""

    n_pairs = P
    faces = ["front", "back"]
    face_extent = EXTENT

    def __init__(self, window=6, fail=False):
        self.window = window
        self.inputs = []
        self.fail = fail

    def read(self, w):
        if self.fail:
            raise RuntimeError("broken model")
        self.inputs.append(np.array(w))
        u = float(np.mean(w))
        return ContactReading(1, 0.9, 0.05, (FingerEstimate("front", u, 50.0, 3.0, 0.7),))


class FakeTrack:
    n_pairs, n_markers = P, M

    def __init__(self, window=4):
        self.window = window
        self.calls = []

    def predict(self, w, init):
        self.calls.append(np.array(w))
        return init


class FakeImager:
    """ECT imager protocol on a 3 x 4 grid per face: the image is delta_c's first 12 values (front)
    and the next 12 negated (back); the peak is the front's largest pixel."""

    faces = ["front", "back"]
    grid_extent = EXTENT

    def __init__(self):
        self.deltas = []

    def image(self, dc):
        self.deltas.append(np.array(dc))
        return {"front": dc[:12].reshape(3, 4), "back": -dc[12:24].reshape(3, 4)}

    def locate(self, dc):
        j = int(np.argmax(dc[:12]))
        return "front", float(j % 4), float(j // 4), float(dc[j])


def _rec(cap, markers=None) -> Recording:
    n = cap.shape[0]
    trial = Trial("t", cap, np.arange(n) / 30.0, np.zeros(n), markers=markers)
    return Recording(LAYOUT, [trial], 30.0)


def _engine(cap, markers=None, **kw):
    src = ReplaySource(_rec(cap, markers), speed=math.inf)
    return LiveEngine(src, policy="block", queue_size=1, **kw)


def _calibrated_window(cap, i, k, c0):
    """Hand-made: frames i-k+1 .. i (the first frame repeated before the stream), Eq. 2."""
    rows = [cap[max(j, 0)] for j in range(i - k + 1, i + 1)]
    return (np.stack(rows) - c0) / c0


def test_contact_window_is_oldest_first_calibrated_against_the_touch_reference():
    n = 40
    rng = np.random.default_rng(3)
    cap = 10 * (1 + 0.01 * np.arange(n))[:, None] * (1 + 0.1 * rng.random(P))
    markers = np.zeros((n, M, 3))
    contact, track = FakeContact(window=6), FakeTrack(window=4)  # the ring is the longer one
    eng = _engine(cap, markers, contact=contact, track=track, reference_frames=3)
    outs = []

    def on_output(o):
        outs.append(o)
        if o.seq == 20:
            eng.capture_reference("touch")  # contact follows; tracking keeps its reference

    eng.run(on_output=on_output)
    c0 = cap[:3].mean(0)
    # frames 2..: the reference exists; the first windows reach back before the stream (padded)
    assert all(o.contact is None for o in outs[:2]) and len(contact.inputs) == n - 2
    for i in range(2, 20):
        np.testing.assert_allclose(
            contact.inputs[i - 2], _calibrated_window(cap, i, 6, c0), rtol=1e-6
        )
        np.testing.assert_allclose(track.calls[i - 2], _calibrated_window(cap, i, 4, c0), rtol=1e-6)
    a, b = eng.reference_state()["touch"]["in_use"]["frames"]
    assert a > 20 and b == a + 2
    c0_new = cap[a : b + 1].mean(0)
    np.testing.assert_allclose(
        contact.inputs[-1], _calibrated_window(cap, n - 1, 6, c0_new), rtol=1e-6
    )
    np.testing.assert_allclose(track.calls[-1], _calibrated_window(cap, n - 1, 4, c0), rtol=1e-6)
    # the reading is the output's, and the message's
    last = outs[-1]
    assert last.contact.fingers[0].u_mm == pytest.approx(float(np.mean(contact.inputs[-1])))
    msg = json.loads(json.dumps(last.to_json_dict(), allow_nan=False))
    assert msg["contact"] == last.contact.to_dict()
    assert msg["ect"] is None
    meta = json.loads(json.dumps(eng.meta(), allow_nan=False))
    assert meta["contact_model"] and meta["contact"] == {
        "faces": ["front", "back"],
        "face_extent": EXTENT,
        "window": 6,
    }
    assert meta["ect"] is None


def test_contact_channels_mapped_by_name_and_masked_channels_fed_as_zero():
    keep = [4, 0, 9]

    class Sub(FakeContact):
        n_pairs = 3
        pair_names = [LAYOUT.pair_names[k] for k in keep]

    cap = np.full((6, P), 10.0) * (1 + 0.01 * np.arange(P))
    cap[:3, 4] = np.nan  # channel 4 has no reference
    cap[3:] *= 1.1
    contact = Sub(window=2)
    _engine(cap, contact=contact, reference_frames=3).run()
    np.testing.assert_allclose(contact.inputs[-1], [[0.0, 0.1, 0.1], [0.0, 0.1, 0.1]], rtol=1e-6)


def test_ect_image_every_nth_frame_on_delta_c_in_pf():
    n = 20
    rng = np.random.default_rng(4)
    cap = 2 + rng.random((n, P))
    cap[:4, 7] = np.nan  # no reference on channel 7: no change there
    imager = FakeImager()
    eng = _engine(cap, imager=imager, ect_every=3, reference_frames=4)
    outs = []
    eng.run(on_output=outs.append)
    c0 = cap[:4].mean(0)  # NaN on channel 7
    imaged = [o.seq for o in outs if o.ect is not None]
    assert imaged == list(range(3, n, 3))  # the reference completes at frame 3
    for seq, dc in zip(imaged, imager.deltas):
        want = cap[seq] - c0
        want[7] = 0.0
        np.testing.assert_allclose(dc, want, rtol=1e-12)
    out = outs[imaged[-1]]
    dc = imager.deltas[-1]
    np.testing.assert_array_equal(out.ect.images["front"], dc[:12].reshape(3, 4))
    j = int(np.argmax(dc[:12]))
    assert (out.ect.face, out.ect.u_mm, out.ect.v_mm, out.ect.peak) == (
        "front",
        j % 4,
        j // 4,
        dc[j],
    )
    # the message carries the image quantised to 0.1 % of its largest magnitude
    msg = json.loads(json.dumps(out.to_json_dict(), allow_nan=False))["ect"]
    assert msg["face"] == "front" and msg["peak"] == pytest.approx(dc[j])
    img = msg["image"]
    assert img["scale"] == pytest.approx(np.abs(dc[:24]).max()) and img["levels"] == ECT_LEVELS
    for face, arr in out.ect.images.items():
        back = np.asarray(img["faces"][face]) * img["scale"] / ECT_LEVELS
        np.testing.assert_allclose(back, arr, atol=img["scale"] / (2 * ECT_LEVELS) + 1e-15)
    assert json.loads(json.dumps(eng.meta()))["ect"] == {
        "faces": ["front", "back"],
        "grid_extent": EXTENT,
        "every": 3,
    }


def test_quantise_by_hand():
    q = quantise({"a": np.array([[0.5, -2.0]]), "b": np.array([[np.nan, 1.0003]])})
    assert q == {"scale": 2.0, "levels": 1000, "faces": {"a": [[250, -1000]], "b": [[None, 500]]}}
    assert quantise({"a": np.zeros((1, 2))})["faces"] == {"a": [[0, 0]]}  # no division by 0


def test_delta_c_by_hand():
    dc = EctHead.delta(np.array([2.0, 3.0, np.nan, 5.0]), np.array([1.5, 0.0, 1.0, np.inf]))
    np.testing.assert_array_equal(dc, [0.5, 0.0, 0.0, 0.0])


def test_failing_heads_are_counted_not_fatal():
    cap = np.full((8, P), 10.0)
    imager = FakeImager()
    imager.locate = None  # calling it fails
    eng = _engine(cap, contact=FakeContact(fail=True), imager=imager, reference_frames=2)
    outs = []
    stats = eng.run(on_output=outs.append)
    assert stats["processed"] == 8 and stats["errors"] == 2 * 7
    assert all(o.contact is None and o.ect is None for o in outs)


def test_heads_are_checked_against_the_layout():
    cap = np.full((3, P), 10.0)

    class Sideways(FakeContact):
        faces = ["front", "top"]

    with pytest.raises(EctskinError, match=r"contact model: faces must be surfaces .*'top'"):
        _engine(cap, contact=Sideways())

    class Short(FakeContact):
        n_pairs = 27

    with pytest.raises(EctskinError, match="contact model expects 27 channels"):
        _engine(cap, contact=Short())
    with pytest.raises(EctskinError, match="window must be an integer >= 1, got 0"):
        _engine(cap, contact=FakeContact(window=0))

    class Flat(FakeContact):
        face_extent = {"front": [[20.0, -20.0], [5.0, 115.0]]}

    with pytest.raises(EctskinError, match=r"face_extent\['front'\] must be .* lo < hi"):
        _engine(cap, contact=Flat())

    imager = FakeImager()
    imager.grid_extent = {"front": EXTENT["front"]}
    with pytest.raises(EctskinError, match=r"grid_extent has no entry for face\(s\) \['back'\]"):
        _engine(cap, imager=imager)
    with pytest.raises(EctskinError, match="every must be an integer >= 1"):
        _engine(cap, imager=FakeImager(), ect_every=0)
    imager = FakeImager()
    imager.n_pairs = 30
    with pytest.raises(EctskinError, match="ECT imager reads 30 pairs, layout"):
        _engine(cap, imager=imager)


class FakeTouch:
    """TouchPredictor protocol; remembers its inputs; class 3."""

    n_pairs, n_classes = P, LAYOUT.n_classes

    def __init__(self):
        self.inputs = []

    def predict(self, x):
        self.inputs.append(np.array(x))
        p = np.full(self.n_classes, 0.01)
        p[3] = 1.0
        return p / p.sum()


def test_every_head_runs_the_same_way_on_its_own_reference():
    """touch, contact and the image on the touch reference, tracking on its own: after the touch
    reference is captured again, only the tracking head's inputs keep the first reference."""
    n = 30
    rng = np.random.default_rng(5)
    cap = 10 * (1 + 0.01 * np.arange(n))[:, None] * (1 + 0.1 * rng.random(P))
    markers = np.zeros((n, M, 3))
    touch, track, contact, imager = FakeTouch(), FakeTrack(window=3), FakeContact(2), FakeImager()
    eng = _engine(
        cap, markers, touch=touch, track=track, contact=contact, imager=imager, reference_frames=3
    )
    assert [(h.key, h.reference, h.window) for h in eng.heads] == [
        ("touch", "touch", 1),
        ("track", "tracking", 3),
        ("contact", "touch", 2),
        ("ect", "touch", 1),
    ]

    def on_output(o):
        if o.seq == 10:
            eng.capture_reference("touch")

    eng.run(on_output=on_output)
    c0 = cap[:3].mean(0)
    a, b = eng.reference_state()["touch"]["in_use"]["frames"]
    c0_new = cap[a : b + 1].mean(0)
    assert a > 10
    # every head answered on the 28 frames from the third on, none before
    assert len(touch.inputs) == len(track.calls) == len(contact.inputs) == len(imager.deltas)
    assert len(touch.inputs) == n - 2
    np.testing.assert_allclose(touch.inputs[0], (cap[2] - c0) / c0, rtol=1e-6)
    np.testing.assert_allclose(touch.inputs[-1], (cap[-1] - c0_new) / c0_new, rtol=1e-6)
    np.testing.assert_allclose(imager.deltas[-1], cap[-1] - c0_new, rtol=1e-12)
    np.testing.assert_allclose(
        contact.inputs[-1], _calibrated_window(cap, n - 1, 2, c0_new), rtol=1e-6
    )
    np.testing.assert_allclose(track.calls[-1], _calibrated_window(cap, n - 1, 3, c0), rtol=1e-6)
    meta = json.loads(json.dumps(eng.meta(), allow_nan=False))
    assert meta["touch"] == {"n_classes": LAYOUT.n_classes}
    assert meta["track"] == {"window": 3, "n_markers": M}
    assert (meta["touch_model"], meta["track_model"], meta["contact_model"]) == (True,) * 3


def test_the_tracking_head_is_checked_against_the_layout():
    cap = np.full((3, P), 10.0)

    class SixMarkers(FakeTrack):
        n_markers = M + 1

    with pytest.raises(EctskinError, match=f"tracking model predicts {M + 1} markers, layout"):
        _engine(cap, track=SixMarkers())
    with pytest.raises(EctskinError, match="tracking model: window must be an integer >= 1, got 0"):
        _engine(cap, track=FakeTrack(window=0))
