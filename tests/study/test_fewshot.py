"""The few-shot study (``ectskin study few-shot``, :mod:`ectskin.study.fewshot`) on a tiny
synthetic problem: the source skin's 28 channels answer a press with Gaussian bumps (the model
of ``tests/learn/press_data.py``, its channel physics and its presses drawn from separate
seeds); the new skin is the same skin with a known linear change of its calibrated readouts,
x' = M x (channel gains and a coupling between neighbouring channels).

What each test catches:

* the draws: a draw that is not nested in N, or that depends on something else than (seed,
  draw); methods that see different frames (the recorded inputs of the real trainings and
  fits are compared), networks whose training and validation frames are not the drawn ones;
* N = 0: a fine-tune curve at N = 0 that is not the source run as ``ectskin evaluate`` scores
  it on the same test trials (another calibration, another window, a model changed in place);
* the physical claim: a fine-tune that does not start from the source (it would do no better
  than scratch) or refits the normaliser on a few frames;
* refusals: N beyond the pool, a touch run as source, another pair count, bad settings.
"""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import Recording, read_recording, write_recording
from ectskin.io.generic import load_generic
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.study import fewshot
from ectskin.study.fewshot import FewShotConfig, draw_frames, few_shot_curve, net_split

N_CH = 28


def _mixing() -> np.ndarray:
    """The known linear change of the new skin: x' = M x on the calibrated readouts."""
    gains = np.random.default_rng(7).uniform(0.5, 1.8, N_CH)
    coupling = 0.35 * np.roll(np.eye(N_CH), 1, axis=1)
    return np.diag(gains) @ (np.eye(N_CH) + coupling)


def _press_file(path, *, press_seed, n_presses, mix=None, n_channels=N_CH, hold=8, gap=3):
    """A generic NPZ of presses on the source skin (``mix``: the new skin's change)."""
    phys = np.random.default_rng(11)
    centre = np.column_stack([phys.uniform(0, 80, n_channels), phys.uniform(0, 30, n_channels)])
    w = phys.uniform(8.0, 18.0, n_channels)
    gain = phys.uniform(0.03, 0.08, n_channels)
    c0 = phys.uniform(0.5, 2.0, n_channels)
    rng = np.random.default_rng(press_seed)
    rows: dict[str, list] = {k: [] for k in ("readouts", "group", "pos", "force")}

    def frame(g, p, f):
        x = np.zeros(n_channels)
        if p is not None and f > 0:
            x = -gain * np.sqrt(f) * np.exp(-np.sum((p - centre) ** 2, axis=1) / (2 * w**2))
        if mix is not None:
            x = mix[:n_channels, :n_channels] @ x
        c = c0 * (1.0 + x) + 2e-4 * c0 * rng.standard_normal(n_channels)
        on = p is not None and f > 0
        rows["readouts"].append(c)
        rows["group"].append(g)
        rows["pos"].append(p if on else np.full(2, np.nan))
        rows["force"].append(float(f) if on else 0.0)

    for r in range(4):
        for _ in range(2 * hold):
            frame(f"rest{r}", None, 0.0)
    for k in range(n_presses):
        p = np.array([rng.uniform(5, 75), rng.uniform(3, 27)])
        for f in np.concatenate([np.zeros(gap), np.linspace(0.5, 3.0, hold), np.zeros(gap)]):
            frame(f"press{k}", p, f)
    on = np.asarray(rows["force"]) > 0
    group = np.asarray(rows["group"], dtype=str)
    np.savez(
        path,
        readouts=np.asarray(rows["readouts"]),
        group=group,
        labels=on.astype(int),
        contact=on,
        position_mm=np.asarray(rows["pos"]),
        force_n=np.asarray(rows["force"]),
        surface=np.where(np.char.startswith(group, "press"), "front", ""),
        frame_rate_hz=30.0,
    )
    h5 = path.with_suffix(".h5")
    write_recording(load_generic(path), h5)
    return h5


@pytest.fixture(scope="module")
def problem(tmp_path_factory):
    """The source run, the new skin's recording and one few-shot curve on them, with the
    inputs every real training and fit received."""
    tmp = tmp_path_factory.mktemp("fewshot")
    source = _press_file(tmp / "source.npz", press_seed=1, n_presses=160)
    new = _press_file(tmp / "new.npz", press_seed=2, n_presses=60, mix=_mixing())
    run = tmp / "source_run"
    train_from_recording(
        "contact", source, run, TrainConfig(profile="quick", epochs=12, window=1, progress=False)
    )
    seen: list[tuple[str, frozenset]] = []

    def frames(data):
        return frozenset(zip(np.asarray(data.group_names)[data.group], data.frame.tolist()))

    import ectskin.design.variability as var
    import ectskin.learn.contact_classical as ccl
    import ectskin.learn.train as lt

    real_train, real_fit = lt.train, ccl.fit_contact_classical

    def train_spy(task, train_data, val_data, out, config, **kw):
        kind = "finetune" if config.init_from else "scratch"
        seen.append((kind, frames(train_data) | frames(val_data)))
        seen.append((kind + "_parts", frozenset({len(frames(train_data) & frames(val_data))})))
        return real_train(task, train_data, val_data, out, config, **kw)

    def fit_spy(name, data, **kw):
        seen.append((name, frames(data)))
        return real_fit(name, data, **kw)

    config = FewShotConfig(frames=(0, 40, 160), draws=2, steps=150)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lt, "train", train_spy)
        mp.setattr(var, "train", train_spy)
        mp.setattr(ccl, "fit_contact_classical", fit_spy)
        doc = few_shot_curve(run, new, tmp / "out", config)
    return {"run": run, "new": new, "source": source, "doc": doc, "seen": seen, "out": tmp / "out"}


def test_draws_are_nested_seeded_and_distinct():
    a = draw_frames(500, (0, 100, 300), 3, seed=4)
    assert a[0][0].size == 0 and [len(d[300]) for d in a] == [300] * 3
    for d in a:
        np.testing.assert_array_equal(d[300][:100], d[100])  # the 100 inside the 300
        assert len(set(d[300].tolist())) == 300
    assert not np.array_equal(a[0][300], a[1][300])  # every draw its own
    b = draw_frames(500, (300, 100), 3, seed=4)  # the order of N changes nothing
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x[100], y[100])
    assert not np.array_equal(draw_frames(500, (100,), 1, seed=5)[0][100], a[0][100])
    tr, va = net_split(20, 5)
    assert va.tolist() == [4, 9, 14, 19] and sorted(tr.tolist() + va.tolist()) == list(range(20))
    assert set(net_split(10, 5)[1]) <= set(va)  # the held-out frames are nested too


def test_every_method_sees_the_same_frames_nested_over_n(problem):
    seen = problem["seen"]
    parts = [s for k, s in seen if k.endswith("_parts")]
    assert parts and all(p == frozenset({0}) for p in parts)  # train and val disjoint
    runs = [(k, s) for k, s in seen if not k.endswith("_parts")]
    # per draw: N = 40 then N = 160, each method once, in the order of the study
    assert [k for k, _ in runs] == ["finetune", "scratch", "knn", "ridge"] * 4
    sets = [s for _, s in runs]
    for i in range(0, 16, 4):
        assert sets[i] == sets[i + 1] == sets[i + 2] == sets[i + 3]
    n40, n160 = sets[0], sets[4]
    assert len(n40) == 40 and len(n160) == 160 and n40 < n160  # nested
    assert sets[8] != n40 and sets[8] < sets[12]  # the second draw: other frames, nested too
    doc = problem["doc"]
    assert doc["draws"][0]["frames"]["40"] != doc["draws"][1]["frames"]["40"]
    test_names = set(doc["split"]["test"])
    assert not any(name in test_names for name, _ in n160)  # drawn from train trials only


def test_n0_finetune_is_the_source_runs_own_evaluation(problem):
    doc = problem["doc"]
    new = read_recording(problem["new"])
    names = set(doc["split"]["test"])
    test_rec = Recording(
        layout=new.layout,
        trials=[t for t in new.trials if t.name in names],
        frame_rate_hz=new.frame_rate_hz,
        meta=dict(new.meta),
    )
    ev = evaluate_run(
        problem["run"],
        test_rec,
        reference=new,
        test_trials="all",
        baselines=False,
        figures=False,
        write=False,
    )["contact"]
    zero = doc["curve"]["0"]["finetune"]
    assert set(doc["curve"]["0"]) == {"finetune"}  # no data, nothing else to fit
    for key in fewshot.METRICS:
        assert zero[key]["values"] == [ev[key], ev[key]], key
        assert zero[key]["std"] == 0.0
        assert doc["source_on_new_skin"][key] == ev[key]


def test_finetuning_beats_scratch_on_a_linearly_changed_skin(problem):
    doc = problem["doc"]
    curve = doc["curve"]
    loc = {n: {m: curve[n][m]["loc_mm_mean"]["mean"] for m in curve[n]} for n in curve}
    for n in ("40", "160"):
        assert loc[n]["finetune"] < 0.8 * loc[n]["scratch"], loc
    # the change matters: the source as it is does worse than after 160 frames of fine-tuning
    assert loc["160"]["finetune"] < 0.8 * loc["0"]["finetune"], loc
    assert (problem["out"] / "few_shot.json").is_file()
    assert (problem["out"] / "few_shot.png").is_file()


def test_refusals(problem, tmp_path, make_recording):
    run, new = problem["run"], problem["new"]
    with pytest.raises(EctskinError, match=r"frames: N = 100000 is more than the \d+ frames"):
        few_shot_curve(run, new, config=FewShotConfig(frames=(0, 100000), draws=1))
    other = _press_file(tmp_path / "other.npz", press_seed=3, n_presses=4, n_channels=15)
    with pytest.raises(EctskinError, match=r"15 pairs, the source run's model reads 28"):
        few_shot_curve(run, other, config=FewShotConfig(frames=(0,), draws=1))
    rec = tmp_path / "touch.h5"
    write_recording(make_recording(n_frames=12), rec)
    touch = tmp_path / "touch_run"
    train_from_recording(
        "touch",
        rec,
        touch,
        TrainConfig(profile="quick", epochs=1, progress=False, counts=(4, 1, 1)),
    )
    with pytest.raises(EctskinError, match=r"field 'task' is 'touch', expected 'contact'"):
        few_shot_curve(touch, new)
    with pytest.raises(EctskinError, match=r"frames: N = 5 is too few"):
        FewShotConfig(frames=(0, 5))
    with pytest.raises(EctskinError, match=r"'method'.*got 'svm'"):
        FewShotConfig(methods=("knn", "svm"))
    with pytest.raises(EctskinError, match=r"steps must be an integer >= 1"):
        FewShotConfig(steps=0)


def test_command_options_are_checked_before_any_work(tmp_path):
    import argparse

    p = argparse.ArgumentParser()
    fewshot.add_arguments(p)
    args = p.parse_args(["RUN", str(tmp_path / "new.h5"), "-o", str(tmp_path / "o")])
    assert (args.frames, args.draws, args.methods) == (
        "0,100,300,1000",
        3,
        "finetune,scratch,knn,ridge",
    )
    bad = p.parse_args(["RUN", "new.h5", "-o", "o", "--frames", "0,12.5"])
    with pytest.raises(EctskinError, match=r"--frames must be whole frame counts"):
        fewshot.run(bad)
    bad = p.parse_args(["RUN", "new.h5", "-o", "o", "--methods", "knn,svm"])
    with pytest.raises(EctskinError, match=r"'method'.*got 'svm'"):
        fewshot.run(bad)
    assert not (tmp_path / "o").exists()


def test_figure_one_panel_per_metric_one_line_per_method():
    from matplotlib.figure import Figure

    from ectskin.viz.variability import plot_few_shot

    def s(m):
        return {k: {"mean": m, "std": 0.1} for k in fewshot.METRICS}

    curve = {
        "0": {"finetune": s(8.0)},
        "100": {"finetune": s(6.0), "knn": s(None)},  # a missing mean is a gap
    }
    fig = plot_few_shot(curve, fewshot.METRICS)
    axes = fig.axes
    assert len(axes) == len(fewshot.METRICS)
    assert [t.get_text() for t in axes[0].get_legend().get_texts()] == ["finetune", "knn"]
    ys = [np.asarray(c.lines[0].get_ydata(), float) for c in axes[0].containers]
    np.testing.assert_array_equal(ys[0], [8.0, 6.0])
    assert len(ys) == 2 and np.isnan(ys[1]).all()
    with pytest.raises(EctskinError, match=r"axes must hold 3 Axes"):
        plot_few_shot(curve, fewshot.METRICS, axes=Figure().subplots(1, 2))
