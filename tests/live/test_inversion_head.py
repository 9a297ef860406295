"""The physical-inversion head: frames made from a response field give its points back through
the live engine (each frame through the field of its state), a stream of a state without a
field is refused, a warm start gives a cold fit's answer while skipping the coarse search, and
the messages (and ``ectskin live --fields``) carry the fitted fingers.

The fields are tiny (a 16 × 20 mm window of the front face, the paper's 28 pairs) with closed-form
node values (each electrode a wire, a fingertip a grounded point coupled to the wires), so no
direct solve is needed; frames are the field's own readouts at points between its nodes plus the
readout's noise, so the truth of every frame is known independently of the inversion.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.cli import main
from ectskin.inversion import Inversion, fit_frames
from ectskin.inversion import fit as fit_module
from ectskin.inversion.model_error import ml_model_error, residuals
from ectskin.inversion.stream import SCREEN_NFEV
from ectskin.io.hdf5 import read_recording, write_recording
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.live import inversion_head
from ectskin.live.engine import LiveEngine
from ectskin.live.inversion_head import (
    BOUND_ERROR_EVERY,
    BOUND_ERROR_FIRST,
    InversionHead,
    load_fields,
)
from ectskin.live.output import InversionFrame, JsonLinesWriter, Output, status_line
from ectskin.live.sources import ReplaySource
from ectskin.twin.field import ResponseField
from ectskin.twin.field_spec import FieldSpec
from ectskin.twin.readout import ReadoutConfig, noise_pf

LAYOUT = default_layout()
P = LAYOUT.n_pairs
WINDOW = ((-8.0, 8.0), (40.0, 60.0))
REST, INFLATED, UNKNOWN = (0.0, 0.0, 0.0), (0.0, 20.0, 0.0), (20.0, 0.0, 0.0)
NOISE = ReadoutConfig()


def tiny_field(state, seed: int) -> ResponseField:
    """A field over ``WINDOW`` of the front face, 2 mm steps, 4 forces, 3 heights; pair (i, j)
    loses α k_i k_j with k_i the segment kernel of wire i (a random u, from a random start to a
    random end along v) at the fingertip, 6 − 1.2 F^(2/3) mm above the face pressing with F and
    6 + h hovering h."""
    spec = FieldSpec(LAYOUT, state, spacing_mm=(2.0, 2.0), faces=("front",), window_mm=WINDOW,
                     force_nodes=4, height_nodes=3, height_range_mm=(1.0, 8.0))
    rng = np.random.default_rng(seed)
    n_e = LAYOUT.n_electrodes
    i, j = np.triu_indices(n_e, 1)
    untouched = rng.uniform(0.5, 3.0, P)
    x = rng.uniform(-10, 10, n_e)
    a, b = rng.uniform(30, 48, n_e), rng.uniform(52, 70, n_e)
    u, v = spec.grid("front")

    def values(z):
        U, V, Z = (g[..., None] for g in np.meshgrid(u, v, z, indexing="ij"))
        rho = np.sqrt((U - x) ** 2 + Z**2)
        k = np.arcsinh((b - V) / rho) - np.arcsinh((a - V) / rho)
        return untouched - 2e-2 * k[..., i] * k[..., j]

    return ResponseField(
        spec, untouched, {"front": values(6.0 - 1.2 * spec.forces() ** (2 / 3))},
        {"front": values(6.0 + spec.heights())},
    )


@pytest.fixture(scope="module")
def fields():
    return {REST: tiny_field(REST, 1), INFLATED: tiny_field(INFLATED, 2)}


@pytest.fixture(scope="module")
def field_dirs(fields, tmp_path_factory):
    """The fields as a field cache: one folder per field, each with its field.npz."""
    root = tmp_path_factory.mktemp("fields")
    for n, f in enumerate(fields.values()):
        f.save(root / f"field{n}" / "field.npz")
    return root


def frame(field, fingers, rng) -> np.ndarray:
    """The field's readout of ``fingers`` [(u, v, force, height)] plus the readout's noise."""
    c = field.untouched.copy()
    for u, v, f, h in fingers:
        c = c + field.delta("front", u, v, f, h)
    return c + rng.standard_normal(P) * noise_pf(c, NOISE)


def slide(n: int, start=(-3.3, 44.1), step=(0.31, 0.27), force=(0.7, 0.02)):
    """n points of a finger sliding: (u, v, force, 0) per frame."""
    return [(start[0] + t * step[0], start[1] + t * step[1], force[0] + t * force[1], 0.0)
            for t in range(n)]


def _recording(fields, trials) -> Recording:
    """A rest trial (the touch reference) and ``trials`` [(name, state, points)]."""
    rng = np.random.default_rng(3)
    out = [Trial("rest", np.stack([frame(fields[REST], [], rng) for _ in range(6)]),
                 np.arange(6) / 30.0, np.zeros(6), inflation=REST)]
    for name, state, points in trials:
        fld = fields.get(state, fields[REST])
        cap = np.stack([frame(fld, [p], rng) for p in points])
        out.append(Trial(name, cap, np.arange(len(points)) / 30.0, np.ones(len(points)),
                         inflation=state, region=1))
    return Recording(LAYOUT, out, 30.0)


def test_the_head_gives_back_the_points_of_frames_made_from_the_field(fields):
    """Each frame is fitted through the field of its own state: frames of the inflated state's
    field come back right only through that field (the rest field's wires lie elsewhere)."""
    pts = {"press": slide(12), "inflated": slide(12, start=(4.2, 57.3), step=(-0.4, -0.3))}
    rec = _recording(fields, [("press", REST, pts["press"]), ("inflated", INFLATED, pts["inflated"])])
    head = InversionHead(Inversion(fields, NOISE), LAYOUT, fields=fields)
    outs: list[Output] = []
    engine = LiveEngine(ReplaySource(rec, speed=math.inf), LAYOUT, inversion=head,
                        reference_frames=6, policy="block")
    stats = engine.run(on_output=outs.append)
    assert stats["errors"] == 0 and stats["processed"] == 30
    assert all(o.inversion is None for o in outs[:5])  # before the reference exists
    assert outs[5].inversion.n_fingers == 0  # the last rest frame: nobody touches
    got = {"press": outs[6:18], "inflated": outs[18:]}
    for name, truth in pts.items():
        for o, (u, v, f, _) in zip(got[name], truth):
            inv = o.inversion
            assert inv.state == tuple(o.inflation)
            assert inv.n_fingers == 1 and inv.fingers[0].face == "front" and inv.fingers[0].contact
            g = inv.fingers[0]
            # within 5 standard errors of the truth (the bound at the fit)
            assert abs(g.u_mm - u) < 5 * g.u_se_mm + 1e-3, (name, g, u)
            assert abs(g.v_mm - v) < 5 * g.v_se_mm + 1e-3, (name, g, v)
            assert abs(g.force_n - f) < 5 * g.force_se_n + 1e-3, (name, g, f)
        # the stream is continuous: every fit after a trial's first starts from the last answer
        assert [o.inversion.warm for o in got[name][1:]] == [True] * 11
    assert not got["inflated"][0].inversion.warm  # a new state starts cold
    # the same frames through the wrong field are not explained
    wrong = Inversion({INFLATED: fields[REST]}, NOISE).fit(got["inflated"][3].raw, INFLATED)
    g = wrong.fingers[0] if wrong.fingers else None
    assert g is None or math.hypot(g.u_mm - pts["inflated"][3][0], g.v_mm - pts["inflated"][3][1]) > 1.0


def test_a_stream_of_a_state_without_a_field_is_refused(fields):
    inv = Inversion(fields, NOISE)
    rec = _recording(fields, [("press", REST, slide(3)), ("odd", UNKNOWN, slide(3))])
    head = InversionHead(inv, LAYOUT)
    with pytest.raises(EctskinError, match=r"without a response field: \[20.0, 0.0, 0.0\] ml"):
        LiveEngine(ReplaySource(rec, speed=math.inf), LAYOUT, inversion=head)
    with pytest.raises(EctskinError, match=r"no response field for --state \[20.0, 0.0, 0.0\]"):
        InversionHead(inv, LAYOUT, state=UNKNOWN)
    # a live frame of such a state (a source that does not say its states in advance)
    out = Output(seq=7, t=0.0, raw=fields[REST].untouched, inflation=UNKNOWN)
    with pytest.raises(EctskinError, match=r"no response field for the frame's inflation"):
        head.state_of(out)
    # a frame without a state: --state, else refused
    bare = Output(seq=8, t=0.0, raw=fields[REST].untouched)
    with pytest.raises(EctskinError, match="carries no inflation state and no --state"):
        head.state_of(bare)
    assert InversionHead(inv, LAYOUT, state=INFLATED).state_of(bare) == INFLATED
    # the head tells states apart as the inversion does
    assert inversion_head.STATE_TOL_ML == fit_module.STATE_TOL_ML
    assert head.state_of(Output(seq=9, t=0.0, raw=bare.raw, inflation=(0.0, 20.0 + 5e-7, 0.0))) == (
        0.0, 20.0 + 5e-7, 0.0)


def test_a_warm_start_gives_the_cold_answer_and_skips_the_coarse_search(fields, monkeypatch):
    field = fields[REST]
    inv = Inversion({REST: field}, NOISE)
    rng = np.random.default_rng(5)
    one = [frame(field, [p], rng) for p in slide(8)]
    # two fingertips at least 17 mm apart (closer than two radii they would overlap)
    two_pts = [[(-5.5 + 0.3 * t, 42.0, 1.2, 0.0), (5.5, 58.0 - 0.3 * t, 0.9, 0.0)] for t in range(6)]
    two = [frame(field, p, rng) for p in two_pts]
    searched = []
    table = type(inv.model(REST).table)
    for name in ("starts", "pairs"):
        real = getattr(table, name)
        monkeypatch.setattr(table, name, lambda self, *a, _f=real, _n=name, **k: (
            searched.append(_n), _f(self, *a, **k))[1])
    for frames, k in ((one, 1), (two, 2)):
        prev = inv.fit(frames[0], REST)
        assert prev.n_fingers == k
        for y in frames[1:]:
            cold = inv.fit(y, REST)
            searched.clear()
            warm = inv.fit(y, REST, warm=prev)
            # the warm fit skips the search of its own count (two fingers: the pairs), and the
            # one-finger fit a BIC needs starts from the warm fit's stronger finger instead of
            # its search
            assert searched == []
            assert warm.n_fingers == cold.n_fingers == k
            for a, b in zip(sorted(warm.fingers, key=lambda f: f.u_mm),
                            sorted(cold.fingers, key=lambda f: f.u_mm)):
                assert (a.face, a.contact) == (b.face, b.contact)
                np.testing.assert_allclose([a.u_mm, a.v_mm, a.force_n], [b.u_mm, b.v_mm, b.force_n],
                                           atol=2e-3)
                np.testing.assert_allclose([a.u_se_mm, a.force_se_n], [b.u_se_mm, b.force_se_n],
                                           rtol=1e-2)
            prev = warm
    # a start that no longer fits (the finger jumped 10 mm) falls back to the coarse search
    jumped = frame(field, [(5.0, 55.0, 1.0, 0.0)], rng)
    searched.clear()
    r = inv.fit(jumped, REST, warm=inv.fit(one[0], REST))
    assert searched == ["starts"]
    assert r.n_fingers == 1 and abs(r.fingers[0].u_mm - 5.0) < 0.3 and abs(r.fingers[0].v_mm - 55.0) < 0.3
    # the finger lifted: no finger, whatever the start
    assert inv.fit(frame(field, [], rng), REST, warm=r).n_fingers == 0
    with pytest.raises(EctskinError, match="warm must be the InversionResult"):
        inv.fit(one[0], REST, warm="last")


def test_difference_readout_takes_per_channel_offsets_off_with_the_reference(fields):
    """A source that reads the field's changes with a stray capacitance of its own per channel:
    against the touch reference (captured untouched, so it holds the strays) the difference
    readout gives the point back; the absolute readout cannot explain the strays."""
    field = fields[REST]
    rng = np.random.default_rng(9)
    stray = rng.uniform(0.2, 0.8, P)
    u, v, f = 2.3, 48.6, 1.2
    raw = frame(field, [(u, v, f, 0.0)], rng) + stray
    c0 = field.untouched + stray
    inv = Inversion({REST: field}, NOISE)
    g = InversionHead(inv, LAYOUT, readout="difference")(raw, c0, REST).fingers[0]
    assert abs(g.u_mm - u) < 5 * g.u_se_mm and abs(g.v_mm - v) < 5 * g.v_se_mm
    assert abs(g.force_n - f) < 5 * g.force_se_n
    bad = InversionHead(inv, LAYOUT)(raw, c0, REST)
    assert bad.n_fingers != 1 or math.hypot(bad.fingers[0].u_mm - u, bad.fingers[0].v_mm - v) > 1.0
    # a channel the reference could not read (NaN) is left out of the fit
    c0[3] = np.nan
    g = InversionHead(inv, LAYOUT, readout="difference")(raw, c0, REST).fingers[0]
    assert abs(g.u_mm - u) < 5 * g.u_se_mm and abs(g.v_mm - v) < 5 * g.v_se_mm


def test_the_message_carries_the_fitted_fingers(fields):
    field = fields[REST]
    inv = Inversion({REST: field}, NOISE)
    r = inv.fit(frame(field, [(1.1, 50.3, 1.0, 0.0)], np.random.default_rng(0)), REST)
    out = Output(seq=1, t=0.5, raw=field.untouched)
    out.inversion = InversionFrame(REST, r.n_fingers, r.fingers, r.bic_by_count, r.converged,
                                   False, 0.8)
    msg = json.loads(json.dumps(out.to_json_dict(), allow_nan=False))["inversion"]
    f = r.fingers[0]
    assert msg["state"] == [0.0, 0.0, 0.0] and msg["n_fingers"] == 1
    assert msg["fingers"] == [{
        "face": "front", "contact": True, "u_mm": f.u_mm, "v_mm": f.v_mm, "force_n": f.force_n,
        "height_mm": 0.0, "u_se_mm": f.u_se_mm, "v_se_mm": f.v_se_mm, "force_se_n": f.force_se_n,
        "height_se_mm": 0.0,
    }]
    # counts not tried have BIC inf: null in strict JSON
    assert msg["bic_by_count"] == [None if math.isinf(b) else b for b in r.bic_by_count]
    assert msg["fit_ms"] == 0.8 and msg["warm"] is False and msg["converged"] is True
    out.stats = {"fps_out": 30.0, "latency_ms_p50": 1.0, "latency_ms_p99": 2.0, "dropped": 0,
                 "malformed": 0, "reconnects": 0}
    assert f"inversion 1: front ({f.u_mm:.1f}, {f.v_mm:.1f}) mm {f.force_n:.2f} N" in status_line(out)
    assert json.loads(json.dumps(Output(seq=2, t=0.0, raw=field.untouched).to_json_dict())
                      )["inversion"] is None


def test_load_fields_reads_a_field_cache_and_refuses_two_of_one_state(fields, field_dirs, tmp_path):
    got = load_fields(field_dirs)
    assert sorted(got) == sorted(fields)
    np.testing.assert_array_equal(got[INFLATED].untouched, fields[INFLATED].untouched)
    assert sorted(load_fields([field_dirs / "field0", field_dirs / "field1" / "field.npz"])) == sorted(fields)
    with pytest.raises(EctskinError, match=r"both fields of state \[0.0, 0.0, 0.0\]"):
        load_fields([field_dirs, field_dirs / "field0"])
    with pytest.raises(EctskinError, match="neither a response field"):
        load_fields(tmp_path)


def test_cli_live_with_fields(fields, field_dirs, tmp_path, capsys):
    pts = slide(10)
    src = write_recording(_recording(fields, [("press", REST, pts)]), tmp_path / "in.h5")
    jsonl = tmp_path / "out.jsonl"
    argv = ["live", "--source", f"replay:{src}", "--speed", "inf", "--policy", "block",
            "--fields", str(field_dirs), "--inversion-every", "2", "--reference-frames", "6",
            "--jsonl", str(jsonl)]
    assert main(argv) == 0
    lines = [json.loads(x) for x in jsonl.read_text().splitlines()]
    assert len(lines) == 16
    fitted = [m["seq"] for m in lines if m["inversion"] is not None]
    assert fitted == list(range(5, 16, 2))  # every 2nd frame from the reference on
    for m in lines[6:]:
        if m["inversion"] is None:
            continue
        (u, v, f, _), g = pts[m["seq"] - 6], m["inversion"]["fingers"][0]
        assert abs(g["u_mm"] - u) < 5 * g["u_se_mm"] + 1e-3
        assert abs(g["v_mm"] - v) < 5 * g["v_se_mm"] + 1e-3
        assert abs(g["force_n"] - f) < 5 * g["force_se_n"] + 1e-3
    assert main(["live", "--source", "sim", "--state", "0", "0", "0"]) == 2
    assert "--state is the inflation state of the inversion's frames: give --fields" in (
        capsys.readouterr().err)
    assert main(argv[:-1] + [str(tmp_path / "b.jsonl"), "--state", "20", "0", "0"]) == 2
    assert "no response field for --state [20.0, 0.0, 0.0]" in capsys.readouterr().err


def test_jsonl_writer_writes_the_inversion(fields, tmp_path):
    out = Output(seq=0, t=0.0, raw=fields[REST].untouched)
    out.inversion = InversionFrame(REST, 0, (), (1.0, math.inf, math.inf), True, False, 0.1)
    out.stats = {}
    with JsonLinesWriter(tmp_path / "o.jsonl") as w:
        w(out)
    msg = json.loads((tmp_path / "o.jsonl").read_text())
    assert msg["inversion"]["fingers"] == [] and msg["inversion"]["bic_by_count"] == [1.0, None, None]


# ---------------------------------------------------------------------------- live vs offline
def _skin(fields, seed: int = 4):
    """A skin whose body differs from the fields' mesh: every readout (untouched or touched, at
    every state) is the field's plus a per-channel offset of up to ±20 σ (a pattern a common
    gain and offset cannot take up, as the twin's body against its field); a rest trial (the
    touch reference) and trials of one finger pressing, one hovering at the field's lowest
    height (1 mm), and one pressing at the inflated state."""
    rng = np.random.default_rng(seed)
    stray = 20 * noise_pf(fields[REST].untouched, NOISE) * rng.uniform(-1, 1, P)
    hover = [(1.0 + 0.4 * t, 50.0 - 0.3 * t, 0.0, 1.0) for t in range(4)]
    trials = [("rest", REST, [None] * 6), ("press", REST, slide(5)), ("hover", REST, hover),
              ("inflated", INFLATED, slide(5, start=(4.2, 57.3), step=(-0.4, -0.3)))]
    out = []
    for name, state, points in trials:
        cap = np.stack([frame(fields[state], [] if p is None else [p], rng) for p in points])
        out.append(Trial(name, cap + stray, np.arange(len(points)) / 30.0,
                         np.zeros(len(points)) if name == "rest" else np.ones(len(points)),
                         inflation=state, region=0 if name == "rest" else 1))
    return Recording(LAYOUT, out, 30.0), stray


def _offline(inv, rec):
    """The reproduction's path: every non-rest trial's frames fitted cold at its state
    (``fit_frames``), in the stream's order."""
    from ectskin.inversion import fit_frames

    return [r for t in rec.trials[1:] for r in fit_frames(inv, t.capacitance, t.inflation)[0]]


def _answers(results):
    """Count, then per finger (face, contact, u, v, force, height)."""
    return [(r.n_fingers, [(f.face, f.contact, f.u_mm, f.v_mm, f.force_n, f.height_mm)
                           for f in r.fingers]) for r in results]


def _same_answers(got, want, atol=1e-9) -> bool:
    if [(n, [g[:2] for g in fs]) for n, fs in got] != [(n, [g[:2] for g in fs]) for n, fs in want]:
        return False
    a = [x for _, fs in got for g in fs for x in g[2:]]
    b = [x for _, fs in want for g in fs for x in g[2:]]
    return bool(np.allclose(a, b, rtol=0, atol=atol))


def test_the_live_head_answers_as_the_reproductions_inversion(fields):
    """``from_fields``' defaults are the reproduction's step's options (``untouched="auto"``,
    ``press_check=True``, ``finger_scale_sd=FINGER_SCALE_SD``): through the engine, each frame's
    answer equals ``Inversion(fields, untouched=..., press_check=True, finger_scale_sd=...)``'s
    cold fit of the same frame, with the untouched readout the skin's own: c_0 (the rest trial's
    mean, computed here) at rest, and c_0 carried by the fields' change of untouched readout at
    the inflated state. Dropping any one of the three options changes some answer (checked)."""
    from ectskin.inversion.fit import FINGER_SCALE_SD

    rec, stray = _skin(fields)
    head = InversionHead.from_fields(fields, LAYOUT, warm=False)  # offline fits are cold
    assert (head.readout, head.inversion.press_check, head.inversion.finger_scale_sd) == (
        "reference", True, FINGER_SCALE_SD)
    outs: list[Output] = []
    engine = LiveEngine(ReplaySource(rec, speed=math.inf), LAYOUT, inversion=head,
                        reference_frames=6, policy="block")
    assert engine.run(on_output=outs.append)["errors"] == 0
    live = _answers([o.inversion for o in outs[6:]])
    c0 = rec.trial("rest").capacitance.mean(axis=0)
    untouched = {REST: c0, INFLATED: c0 + fields[INFLATED].untouched - fields[REST].untouched}
    # the carried offset is this skin's own at the inflated state (its body offset is one)
    np.testing.assert_allclose(untouched[INFLATED], fields[INFLATED].untouched + stray,
                               atol=5 * noise_pf(c0, NOISE).max())

    def offline(**kw):
        opts = {"untouched": untouched, "press_check": True, "finger_scale_sd": FINGER_SCALE_SD}
        return _answers(_offline(Inversion(fields, NOISE, **{**opts, **kw}), rec))

    assert _same_answers(live, offline())
    for dropped in ({"untouched": None}, {"press_check": False}, {"finger_scale_sd": None}):
        assert not _same_answers(live, offline(**dropped)), dropped
    # the pressing frames' truth comes back (the hovering finger's, at the field's edge, is not
    # a test of the head); the field's untouched readout cannot explain the skin's offsets
    truth = {i: p for i, p in enumerate(slide(5))} | {
        9 + i: p for i, p in enumerate(slide(5, start=(4.2, 57.3), step=(-0.4, -0.3)))}
    for i, (u, v, *_) in truth.items():
        n, fingers = live[i]
        assert n == 1 and fingers[0][1] and math.hypot(fingers[0][2] - u, fingers[0][3] - v) < 0.5
    plain = _answers(_offline(Inversion(fields, NOISE), rec))
    assert sum(plain[i][0] != 1 or math.hypot(plain[i][1][0][2] - u, plain[i][1][0][3] - v) > 0.5
               for i, (u, v, *_) in truth.items()) >= len(truth) // 2


def test_the_reference_readout_masks_and_carries(fields):
    """readout "reference" directly: a channel without a usable reference (NaN) is left out of
    the fit (its untouched readout the field's); c_0 captured at a state without a field gives
    the field's own untouched readout; the reference is rebuilt only when c_0 changes; it needs
    a way to rebuild the inversion."""
    from ectskin.inversion.fit import FINGER_SCALE_SD

    field = fields[REST]
    rng = np.random.default_rng(11)
    stray = 20 * noise_pf(field.untouched, NOISE) * rng.uniform(-1, 1, P)
    raw = frame(field, [(2.3, 48.6, 1.2, 0.0)], rng) + stray
    c0 = field.untouched + stray
    c0[3] = np.nan
    head = InversionHead.from_fields(fields, LAYOUT, warm=False)
    got = _answers([head(raw, c0, REST)])
    cu = np.where(np.isnan(c0), field.untouched, c0)
    masked = np.where(np.isnan(c0), np.nan, raw)
    want = Inversion({REST: field}, NOISE, untouched={REST: cu}, press_check=True,
                     finger_scale_sd=FINGER_SCALE_SD).fit(masked, REST)
    assert _same_answers(got, _answers([want]))
    built = head._built[REST][2]
    head(raw, c0.copy(), REST)  # the same reference (another array): not rebuilt
    assert head._built[REST][2] is built
    head(raw, c0 + 1e-3, REST)
    assert head._built[REST][2] is not built
    # c_0 of a state without a field: the field's untouched readout (the base inversion)
    cu, mask = head.untouched(c0, REST, UNKNOWN)
    assert cu is None and not mask.any()
    assert _same_answers(_answers([head(raw, c0, REST, reference_state=UNKNOWN)]),
                         _answers([head.inversion.fit(raw, REST)]))
    with pytest.raises(EctskinError, match="readout 'reference' rebuilds the inversion"):
        InversionHead(Inversion(fields, NOISE), LAYOUT, readout="reference")
    with pytest.raises(EctskinError, match="--inversion-finger-sd must be a number >= 0"):
        InversionHead.from_fields(fields, LAYOUT, finger_scale_sd=-0.1)


def test_cli_inversion_options_reach_the_head(fields, field_dirs, tmp_path, monkeypatch, capsys):
    """``--no-inversion-press-check --inversion-finger-sd 0 --inversion-readout absolute`` reach
    the head (its meta) and its answers (those of the inversion with those options); the defaults
    are the reproduction's."""
    from ectskin.commands import live as live_cmd
    from ectskin.inversion.fit import FINGER_SCALE_SD

    rec, _ = _skin(fields)
    src = write_recording(rec, tmp_path / "in.h5")
    heads = []
    real = live_cmd._inversion
    monkeypatch.setattr(live_cmd, "_inversion", lambda *a: heads.append(real(*a)) or heads[-1])

    def run(name, *extra):
        out = tmp_path / f"{name}.jsonl"
        argv = ["live", "--source", f"replay:{src}", "--speed", "inf", "--policy", "block",
                "--fields", str(field_dirs), "--reference-frames", "6", "--jsonl", str(out),
                *extra]
        assert main(argv) == 0
        return [json.loads(x)["inversion"] for x in out.read_text().splitlines()][6:]

    default = run("default")
    off = run("off", "--no-inversion-press-check", "--inversion-finger-sd", "0",
              "--inversion-readout", "absolute")
    meta = [{k: h.meta()[k] for k in ("readout", "press_check", "finger_scale_sd")} for h in heads]
    assert meta == [{"readout": "reference", "press_check": True, "finger_scale_sd": FINGER_SCALE_SD},
                    {"readout": "absolute", "press_check": False, "finger_scale_sd": None}]
    assert run("sd", "--inversion-finger-sd", "0.3", "--record", str(tmp_path / "sd.h5"))[0] is not None
    assert heads[-1].inversion.finger_scale_sd == 0.3
    # the recording says how its inversion was made
    stored = read_recording(tmp_path / "sd.h5").meta["inversion"]
    assert (stored["finger_scale_sd"], stored["press_check"], stored["readout"]) == (0.3, True, "reference")
    # the answers of the flags-off run are the plain inversion's, each fit started from the
    # previous frame's answer as the head does (from the reference's last frame on)
    inv, prev, want = Inversion(fields, NOISE), None, []
    frames = [(y, t.inflation) for t in rec.trials for y in t.capacitance][5:]
    for i, (y, state) in enumerate(frames):
        r = inv.fit(y, state, warm=prev if prev is not None and frames[i - 1][1] == state else None)
        prev = r if r.n_fingers else None
        want.append(r)

    def answers(msgs):
        return [(m["n_fingers"], [(f["face"], f["contact"], f["u_mm"], f["v_mm"], f["force_n"],
                                   f["height_mm"]) for f in m["fingers"]]) for m in msgs]

    assert _same_answers(answers(off), _answers(want[1:]))
    assert not _same_answers(answers(off), answers(default), atol=1e-3)
    assert main(["live", "--source", "sim", "--fields", str(field_dirs),
                 "--inversion-finger-sd", "-1"]) == 2
    assert "--inversion-finger-sd must be a number >= 0 (0: off), got -1.0" in capsys.readouterr().err


# ------------------------------------------------------------ the person's finger, pooled
#: a frame read with this noise tells the pulp about as well as the population's prior does
NOISY = ReadoutConfig(noise_scale=6.0)


def modulus_table(field):
    """∂C/∂ln E of the tiny field's fingertip in closed form (tests/inversion/test_modulus.py's
    model): a softer pulp presses deeper, as a larger force does, and spreads its pad (the
    signal's discrete Laplacian over 3 mm, kept in the window)."""
    from ectskin.twin.bound_modulus import ModulusTable

    (u0, u1), (v0, v1) = WINDOW
    u, v = np.linspace(u0, u1, 9), np.linspace(v0, v1, 11)
    forces = np.exp(np.linspace(*np.log(field.spec.force_range_n), 4))
    U, V, F = np.meshgrid(u, v, forces, indexing="ij")
    d0 = field.delta("front", U, V, F)
    lap = sum(field.delta("front", np.clip(U + a, u0, u1), np.clip(V + b, v0, v1), F)
              for a, b in ((3, 0), (-3, 0), (0, 3), (0, -3))) - 4 * d0
    col = -0.5 * F[..., None] * field.jacobian("front", U, V, F)[..., 2] - 0.6 * lap
    return ModulusTable({"front": (u, v)}, forces, {"front": col}, 0.1)


def person_recording(field, table, people, rng) -> Recording:
    """A rest trial and one trial per person [(name, x, points)]: the field's readout plus
    x times the table's column (x = ln(E / E0) of their pulp), read with ``NOISY``."""
    def read(c):
        return c + rng.standard_normal(P) * noise_pf(c, NOISY)
    out = [Trial("rest", np.stack([read(field.untouched) for _ in range(6)]),
                 np.arange(6) / 30.0, np.zeros(6), inflation=REST)]
    for name, x, points in people:
        cap = np.stack([read(field.readout("front", u, v, f) + x * table.column(
            "front", np.array([[u, v]]), np.array([f]))[0]) for u, v, f, _ in points])
        out.append(Trial(name, cap, np.arange(len(points)) / 30.0, np.ones(len(points)),
                         inflation=REST, region=1))
    return Recording(LAYOUT, out, 30.0)


def test_the_head_pools_each_persons_finger_over_the_stream(fields):
    """Two people (pulp x = +0.5, then −0.4) press 30 frames each, read with 6× the noise: each
    frame's own fit is pulled towards 0 by the population's prior. With ``person="trial"`` the
    head pools as the frames come and restarts at the second trial; at each trial's end the
    pool's centre lies within 3 sd (and 0.12) of the truth, and in each trial's second half the
    frames' x and force come closer to the truth than without pooling. The message carries
    the pool."""
    field = fields[REST]
    table = modulus_table(field)
    rng = np.random.default_rng(5)
    people = [("anna", 0.5, slide(30)), ("ben", -0.4, slide(30, start=(3.1, 57.2),
                                                          step=(-0.25, -0.33)))]
    rec = person_recording(field, table, people, rng)
    inv = Inversion({REST: field}, NOISY, modulus={REST: table}, max_fingers=1)
    got = {}
    for person in ("trial", "off"):
        outs: list[Output] = []
        head = InversionHead(inv, LAYOUT, person=person)
        LiveEngine(ReplaySource(rec, speed=math.inf), LAYOUT, inversion=head,
                   reference_frames=6, policy="block").run(on_output=outs.append)
        got[person] = {name: outs[6 + 30 * k: 36 + 30 * k] for k, (name, _, _) in
                       enumerate(people)}
    for name, x, points in people:
        pooled, plain = got["trial"][name], got["off"][name]
        assert all(o.trial == name and o.inversion.n_fingers == 1 for o in pooled + plain)
        first, last = pooled[0].inversion.finger, pooled[-1].inversion.finger
        assert first["frames"] == 1  # a new person at the trial's first frame
        assert last["frames"] == 30
        centre, sd = last["modulus_ln"]
        assert abs(centre - x) < max(3 * sd, 0.12), (name, centre, sd)
        assert all(o.inversion.finger is None for o in plain)
        late = slice(15, 30)
        err = {k: (np.mean([abs(o.inversion.fingers[0].modulus_ln - x) for o in g[late]]),
                   np.mean([abs(o.inversion.fingers[0].force_n - p[2])
                            for o, p in zip(g[late], points[late])]))
               for k, g in (("trial", pooled), ("off", plain))}
        assert err["trial"][0] < 0.6 * err["off"][0], (name, err)
        assert err["trial"][1] < err["off"][1], (name, err)
    msg = json.loads(json.dumps(got["trial"]["ben"][-1].to_json_dict(), allow_nan=False))
    assert msg["inversion"]["finger"] == {"modulus_ln": last["modulus_ln"], "frames": 30}
    head = InversionHead(inv, LAYOUT, person="session")
    assert head.meta()["person"] == "session" and head.meta()["finger_nuisances"] == ["modulus"]
    with pytest.raises(EctskinError, match="finger tables"):
        InversionHead(Inversion({REST: field}), LAYOUT, person="session")
    with pytest.raises(EctskinError, match="'person'"):
        InversionHead(inv, LAYOUT, person="everyone")
    for bad in ({"pulp": {REST: table}}, [table]):
        with pytest.raises(EctskinError, match="finger_tables must be"):
            InversionHead.from_fields(fields, LAYOUT, finger_tables=bad)


def test_cli_live_pools_the_person_with_the_finger_fields(fields, field_dirs, tmp_path,
                                                          monkeypatch, capsys):
    """``--inversion-person session`` reads the finger tables of the fields' states from
    ``--finger-fields`` (:func:`ectskin.twin.field_finger.finger_tables`, here the closed-form
    table) and the messages carry the pool; ``--finger-fields`` alone is refused."""
    from ectskin.twin import field_finger

    table = modulus_table(fields[REST])
    calls = []

    def tables(specs, cache_dir, **kw):
        calls.append(([tuple(s.inflation_ml) for s in specs], str(cache_dir)))
        return {"modulus": {REST: table}}

    monkeypatch.setattr(field_finger, "finger_tables", tables)
    rec = person_recording(fields[REST], table, [("press", 0.3, slide(10))],
                           np.random.default_rng(2))
    src = write_recording(rec, tmp_path / "in.h5")
    jsonl = tmp_path / "out.jsonl"
    argv = ["live", "--source", f"replay:{src}", "--speed", "inf", "--policy", "block",
            "--fields", str(field_dirs), "--reference-frames", "6", "--jsonl", str(jsonl),
            "--inversion-person", "session", "--finger-fields", str(tmp_path / "cache")]
    assert main(argv) == 0
    assert len(calls) == 1 and sorted(calls[0][0]) == sorted([REST, INFLATED])
    assert calls[0][1] == str(tmp_path / "cache")
    lines = [json.loads(x) for x in jsonl.read_text().splitlines()]
    frames = [m["inversion"]["finger"]["frames"] for m in lines[6:]]
    assert frames == list(range(1, 11))
    assert main(argv[:-4] + ["--finger-fields", str(tmp_path)]) == 2
    assert "--finger-fields is where --inversion-person reads" in capsys.readouterr().err


# ------------------------------------------------------------ the standard errors' model error
#: the share of each channel's signal the tiny field does not know in these frames, drawn per
#: frame (the references: the batch estimate of cold offline fits' residuals, and those frames'
#: standard errors with that floor; the labels only score the coverage)
SHARE = 0.03
N = BOUND_ERROR_FIRST + BOUND_ERROR_EVERY + 40


def _error_frames(field, n: int, seed: int):
    rng = np.random.default_rng(seed)
    (u0, u1), (v0, v1) = WINDOW
    truth = np.column_stack([rng.uniform(u0 + 2, u1 - 2, n), rng.uniform(v0 + 2, v1 - 2, n),
                             rng.uniform(0.4, 1.6, n)])
    y = []
    for u, v, f in truth:
        d = field.delta("front", u, v, f, 0.0)
        c = field.untouched + d * (1 + SHARE * rng.standard_normal(d.shape))
        y.append(c + rng.standard_normal(c.shape) * NOISE.resolution_pf)
    return np.array(y), truth


def test_the_session_learns_the_model_error_and_the_standard_errors_carry_it(fields):
    field = fields[REST]
    y, truth = _error_frames(field, N, seed=11)
    inv = Inversion({REST: field}, NOISE, max_fingers=1)
    plain = InversionHead(inv, LAYOUT, warm=False)
    head = InversionHead(inv, LAYOUT, warm=False, bound_error="session")
    got = [head(y[i], field.untouched, REST) for i in range(N)]
    base = [plain(y[i], field.untouched, REST) for i in range(N)]
    # the reference: cold offline fits, their residuals, the batch estimate
    offline, _ = fit_frames(inv, y, REST)
    e, s, d, h = residuals(inv, y, REST, offline)
    first = ml_model_error(e[:BOUND_ERROR_FIRST], s[:BOUND_ERROR_FIRST], d[:BOUND_ERROR_FIRST],
                           h[:BOUND_ERROR_FIRST])
    k = BOUND_ERROR_FIRST + BOUND_ERROR_EVERY
    second = ml_model_error(e[:k], s[:k], d[:k], h[:k])
    assert first.r == pytest.approx(SHARE, rel=0.3)
    for i in range(N):
        want = None if i < BOUND_ERROR_FIRST else first if i < k else second
        g, b = got[i], base[i]
        if want is None:
            assert g.model_error is None
        else:
            assert g.model_error == {"a_pf": want.a_pf, "r": want.r, "frames": want.n_frames}
        # the fits are the plain head's; the standard errors those of the floor in use
        assert (g.fingers[0].u_mm, g.fingers[0].force_n) == (b.fingers[0].u_mm, b.fingers[0].force_n)
        ref = inv if want is None else inv.with_bound_error(want.floor)
        assert g.fingers[0].force_se_n == pytest.approx(ref.fit(y[i], REST).fingers[0].force_se_n,
                                                        rel=1e-9)
    # after the first estimate the force's error bars cover; the noise's alone do not
    late = slice(BOUND_ERROR_FIRST, N)
    press = np.array([o.fingers[0].contact for o in got[late]])
    assert press.mean() > 0.9

    def cover(outs):
        f = np.array([[o.fingers[0].force_n, o.fingers[0].force_se_n] for o in outs[late]])
        z = np.abs(f[press, 0] - truth[late][press, 2]) / f[press, 1]
        return np.mean(z < 1), np.mean(z < 2)

    assert cover(base)[1] < 0.6
    assert 0.55 < cover(got)[0] < 0.85 and cover(got)[1] > 0.88
    assert head.meta()["bound_error"] == "session"


def test_a_known_floor_is_used_from_the_first_frame_and_bad_ones_are_named(fields):
    field = fields[REST]
    y, _ = _error_frames(field, 3, seed=12)
    inv = Inversion({REST: field}, NOISE, max_fingers=1)
    head = InversionHead(inv, LAYOUT, bound_error=(2e-4, 0.01))
    out = head(y[0], field.untouched, REST)
    assert out.model_error == {"a_pf": 2e-4, "r": 0.01, "frames": None}
    assert out.fingers[0].force_se_n == inv.with_bound_error((2e-4, 0.01)).fit(
        y[0], REST).fingers[0].force_se_n
    assert head.meta()["bound_error"] == [2e-4, 0.01]
    with pytest.raises(EctskinError, match="bound_error"):
        InversionHead(inv, LAYOUT, bound_error=(-1.0, 0.0))
    with pytest.raises(EctskinError, match="allowed values"):
        InversionHead(inv, LAYOUT, bound_error="always")


def test_cli_live_takes_a_floor_and_names_a_bad_one(fields, field_dirs, tmp_path, capsys):
    src = write_recording(_recording(fields, [("press", REST, slide(6))]), tmp_path / "in.h5")
    jsonl = tmp_path / "out.jsonl"
    argv = ["live", "--source", f"replay:{src}", "--speed", "inf", "--policy", "block",
            "--fields", str(field_dirs), "--reference-frames", "6", "--jsonl", str(jsonl)]
    assert main(argv + ["--inversion-bound-error", "0.0002,0.01"]) == 0
    msgs = [json.loads(x)["inversion"] for x in jsonl.read_text().splitlines()]
    fitted = [m for m in msgs if m is not None]
    assert fitted and all(m["model_error"] == {"a_pf": 2e-4, "r": 0.01, "frames": None}
                          for m in fitted)
    # the default learns from the session: the noise alone before its first estimate
    assert main(argv[:-1] + [str(tmp_path / "b.jsonl")]) == 0
    msgs = [json.loads(x)["inversion"] for x in (tmp_path / "b.jsonl").read_text().splitlines()]
    assert all(m["model_error"] is None for m in msgs if m is not None)
    assert main(argv[:-1] + [str(tmp_path / "c.jsonl"), "--inversion-bound-error", "1,x"]) == 2
    assert "--inversion-bound-error must be session, off or A,R" in capsys.readouterr().err


def test_a_stream_of_two_fingers_screens_the_one_finger_fit_and_keeps_its_answers(fields,
                                                                                  monkeypatch):
    """From a warm start of two fingers that explains the frame, the one-finger fit runs on the
    screen's budget and stops there; the answers are those of the full budget; and when a finger
    lifts, the smaller count that explains the frame is still found."""
    field = fields[REST]
    inv = Inversion({REST: field}, NOISE)
    rng = np.random.default_rng(11)
    pts = [[(-5.5 + 0.3 * t, 42.0, 1.2, 0.0), (5.5, 58.0 - 0.3 * t, 0.9, 0.0)] for t in range(6)]
    frames = [frame(field, p, rng) for p in pts]
    lifted = frame(field, [(-3.7, 42.0, 1.2, 0.0)], rng)  # the second finger gone
    budgets = []
    real = fit_module.Inversion._fit_fingers

    def recording(m, delta, sigma, start, coupled=False, **kw):
        budgets.append((len(start), kw.get("max_nfev")))
        return real(m, delta, sigma, start, coupled, **kw)

    def stream_of(screen: bool):
        monkeypatch.setattr(fit_module.Inversion, "_fit_fingers", staticmethod(recording))
        if not screen:  # every count on the full budget
            monkeypatch.setattr(fit_module, "screened",
                                lambda fit, m, d, s, st, c, g: fit(m, d, s, st, c))
        out, prev = [], inv.fit(frames[0], REST)
        for y in frames[1:] + [lifted]:
            budgets.clear()
            prev = inv.fit(y, REST, warm=prev)
            out.append((prev, list(budgets)))
        monkeypatch.undo()
        return out

    screened, full = stream_of(True), stream_of(False)
    for (a, calls), (b, _) in zip(screened[:-1], full[:-1]):
        # the warm two-finger fit, then the one-finger fit on the screen's budget alone
        assert calls == [(2, None), (1, SCREEN_NFEV)]
        assert a.n_fingers == b.n_fingers == 2
        for fa, fb in zip(a.fingers, b.fingers):
            np.testing.assert_allclose([fa.u_mm, fa.v_mm, fa.force_n], [fb.u_mm, fb.v_mm, fb.force_n],
                                       rtol=0, atol=1e-9)
    r, _ = screened[-1]
    assert r.n_fingers == full[-1][0].n_fingers == 1
    assert abs(r.fingers[0].u_mm + 3.7) < 0.3 and abs(r.fingers[0].v_mm - 42.0) < 0.3
