"""The touch few-shot study (``ectskin study few-shot-touch``, :mod:`ectskin.study.fewshot_touch`)
on a tiny synthetic problem: 28 channels answer a press with Gaussian bumps around the press
point, twelve regions on a 4 × 3 grid, the touch class the pressed region; the new skin is the
same skin with a known linear change of its calibrated readouts, x' = M x (channel gains and an
equal coupling of each channel with its neighbour).

What each test catches:

* the draws: methods that see different frames, draws not nested in N, networks whose training
  and validation frames are not the drawn ones (the recorded inputs of the real trainings and
  fits are compared);
* N = 0: a fine-tune curve at N = 0 that is not the source run as ``ectskin evaluate`` scores
  it on the same test trials (another calibration, a model changed in place);
* the physical claim: a fine-tune that does not start from the source (it would do no better
  than scratch, at a lower learning rate), or that does not train (it would stay the source);
* the scores against a hand count, the reference mode taken from the source run, refusals (a
  contact method name, more classes than the source knows, another pair count, N beyond the
  pool, a contact run's study config).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import Recording, read_recording, write_recording
from ectskin.io.generic import load_generic
from ectskin.learn.evaluate import evaluate_run
from ectskin.learn.train import TrainConfig, train_from_recording
from ectskin.study import fewshot_touch
from ectskin.study.fewshot import FewShotConfig
from ectskin.study.fewshot_touch import (
    TouchFewShotConfig,
    few_shot_touch_curve,
    scores,
    source_reference,
)

N_CH = 28
#: region centres (mm), class k + 1 at CENTRES[k]
CENTRES = np.array([(10.0 + 20.0 * i, 5.0 + 10.0 * j) for j in range(3) for i in range(4)])


def _mixing() -> np.ndarray:
    """The known linear change of the new skin: x' = M x on the calibrated readouts (strong
    enough that the source run misreads about 40 % of the touched frames)."""
    gains = np.random.default_rng(7).uniform(0.3, 2.5, N_CH)
    coupling = np.roll(np.eye(N_CH), 1, axis=1)
    return np.diag(gains) @ (np.eye(N_CH) + coupling)


def _touch_file(path, *, seed, per_region, mix=None, n_channels=N_CH, regions=12, hold=8, gap=3):
    """A generic NPZ of presses on the source skin (``mix``: the new skin's change), then its
    HDF5 import."""
    phys = np.random.default_rng(11)
    centre = np.column_stack([phys.uniform(0, 80, n_channels), phys.uniform(0, 30, n_channels)])
    w = phys.uniform(8.0, 18.0, n_channels)
    gain = phys.uniform(0.03, 0.08, n_channels)
    c0 = phys.uniform(0.5, 2.0, n_channels)
    rng = np.random.default_rng(seed)
    rows: dict[str, list] = {"readouts": [], "group": [], "labels": []}

    def frame(g, label, p, f):
        x = np.zeros(n_channels)
        if label:
            x = -gain * np.sqrt(f) * np.exp(-np.sum((p - centre) ** 2, axis=1) / (2 * w**2))
        if mix is not None:
            x = mix[:n_channels, :n_channels] @ x
        rows["readouts"].append(c0 * (1.0 + x) + 2e-4 * c0 * rng.standard_normal(n_channels))
        rows["group"].append(g)
        rows["labels"].append(label)

    for r in range(4):
        for _ in range(2 * hold):
            frame(f"rest{r}", 0, None, 0.0)
    k = 0
    for _ in range(per_region):
        for region in range(regions):
            p = CENTRES[region % len(CENTRES)] + rng.uniform(-3.0, 3.0, 2)
            for f in np.linspace(0.5, 3.0, hold):
                frame(f"press{k}", 0 if f == 0 else region + 1, p, f)
            for _ in range(gap):
                frame(f"press{k}", 0, None, 0.0)
            k += 1
    np.savez(
        path,
        readouts=np.asarray(rows["readouts"]),
        group=np.asarray(rows["group"], dtype=str),
        labels=np.asarray(rows["labels"], dtype=np.int64),
        frame_rate_hz=30.0,
    )
    h5 = path.with_suffix(".h5")
    write_recording(load_generic(path), h5)
    return h5


@pytest.fixture(scope="module")
def problem(tmp_path_factory):
    """The source touch run, the new skin's recording and one few-shot curve on them, with the
    inputs every real training and fit received."""
    tmp = tmp_path_factory.mktemp("fewshot_touch")
    source = _touch_file(tmp / "source.npz", seed=1, per_region=10)
    new = _touch_file(tmp / "new.npz", seed=2, per_region=5, mix=_mixing())
    run = tmp / "source_run"
    train_from_recording(
        "touch", source, run, TrainConfig(profile="quick", epochs=40, progress=False)
    )
    seen: list[tuple[str, frozenset]] = []

    def frames(data):
        # (trial, readout) identifies a frame: the readouts carry their own noise
        names = np.asarray(data.group_names)[data.group]
        return frozenset(zip(names, map(bytes, np.asarray(data.x, np.float32))))

    import ectskin.design.variability as var
    import ectskin.learn.baselines.touch as blt
    import ectskin.learn.train as lt

    real_train, real_fit = lt.train, blt.sklearn_touch_baseline

    def train_spy(task, train_data, val_data, out, config, **kw):
        kind = "finetune" if config.init_from else "scratch"
        seen.append((kind, frames(train_data) | frames(val_data)))
        seen.append((kind + "_parts", frozenset({len(frames(train_data) & frames(val_data))})))
        return real_train(task, train_data, val_data, out, config, **kw)

    def fit_spy(name, train, test, **kw):
        seen.append((name, frames(train)))
        return real_fit(name, train, test, **kw)

    config = TouchFewShotConfig(frames=(0, 40, 160), draws=2, steps=150)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lt, "train", train_spy)
        mp.setattr(var, "train", train_spy)
        mp.setattr(blt, "sklearn_touch_baseline", fit_spy)
        doc = few_shot_touch_curve(run, new, tmp / "out", config)
    return {"run": run, "new": new, "doc": doc, "seen": seen, "out": tmp / "out", "tmp": tmp}


def test_every_method_sees_the_same_frames_nested_over_n(problem):
    seen = problem["seen"]
    parts = [s for k, s in seen if k.endswith("_parts")]
    assert parts and all(p == frozenset({0}) for p in parts)  # train and val disjoint
    runs = [(k, s) for k, s in seen if not k.endswith("_parts")]
    assert [k for k, _ in runs] == ["finetune", "scratch", "logreg", "knn"] * 4
    sets = [s for _, s in runs]
    for i in range(0, 16, 4):
        assert sets[i] == sets[i + 1] == sets[i + 2] == sets[i + 3]
    n40, n160 = sets[0], sets[4]
    assert len(n40) == 40 and len(n160) == 160 and n40 < n160  # nested
    assert sets[8] != n40 and sets[8] < sets[12]  # the second draw: other frames, nested too
    doc = problem["doc"]
    assert doc["task"] == "touch" and doc["reference"] == {"mode": "rest"}
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
    )["touch"]
    zero = doc["curve"]["0"]["finetune"]
    assert set(doc["curve"]["0"]) == {"finetune"}  # no data, nothing else to fit
    assert zero["accuracy"]["values"] == [ev["accuracy"], ev["accuracy"]]
    assert zero["accuracy"]["std"] == 0.0
    assert doc["source_on_new_skin"]["accuracy"] == ev["accuracy"]
    assert doc["source_on_new_skin"]["n_frames"] == ev["n_test_frames"]


def test_finetuning_beats_scratch_on_a_linearly_changed_skin(problem):
    curve = problem["doc"]["curve"]
    acc = {n: {m: curve[n][m]["touch_accuracy"]["mean"] for m in curve[n]} for n in curve}
    # measured: source 0.61; N = 160: fine-tune 1.00, scratch 0.82, logreg 0.98, k-NN 0.90
    assert acc["160"]["finetune"] > acc["160"]["scratch"] + 0.1, acc
    # the change matters: the source as it is does worse than after 160 frames of fine-tuning
    assert acc["160"]["finetune"] > acc["0"]["finetune"] + 0.2, acc
    assert (problem["out"] / "few_shot.json").is_file()
    assert (problem["out"] / "few_shot.png").is_file()


def test_scores_against_a_hand_count():
    test = SimpleNamespace(y=np.array([0, 0, 1, 2, 3]))
    got = scores(test, np.array([0, 1, 1, 0, 3]))
    assert got == {"accuracy": 3 / 5, "touch_accuracy": 2 / 3, "n_frames": 5, "n_touch_frames": 3}
    assert scores(SimpleNamespace(y=np.zeros(2, int)), np.zeros(2, int))["touch_accuracy"] is None


def test_the_reference_follows_the_source_run():
    def run(split, extra=None):
        return SimpleNamespace(split=split, payload={"extra": extra or {}})

    assert source_reference(run({})) == "auto"
    assert source_reference(run({"touch_reference": {"mode": "rest"}})) == "auto"
    assert source_reference(run({"touch_reference": {"mode": "state"}})) == "state"
    assert source_reference(run({}, {"reference": {"mode": "inflation", "model": {}}})) == (
        "inflation"
    )


def test_refusals(problem):
    run, new, tmp = problem["run"], problem["new"], problem["tmp"]
    with pytest.raises(EctskinError, match=r"frames: N = 100000 is more than the \d+ frames"):
        few_shot_touch_curve(run, new, config=TouchFewShotConfig(frames=(0, 100000), draws=1))
    more = _touch_file(tmp / "more.npz", seed=3, per_region=1, regions=14)
    with pytest.raises(EctskinError, match=r"15 touch classes, the source run's model knows 13"):
        few_shot_touch_curve(run, more, config=TouchFewShotConfig(frames=(0,), draws=1))
    fewer = _touch_file(tmp / "fewer.npz", seed=3, per_region=1, n_channels=15)
    with pytest.raises(EctskinError, match=r"15 pairs, the source run's model reads 28"):
        few_shot_touch_curve(run, fewer, config=TouchFewShotConfig(frames=(0,), draws=1))
    with pytest.raises(EctskinError, match=r"'method'.*got 'ridge'"):
        TouchFewShotConfig(methods=("knn", "ridge"))
    with pytest.raises(EctskinError, match=r"config must be a TouchFewShotConfig"):
        few_shot_touch_curve(run, new, config=FewShotConfig(frames=(0,), draws=1))
    with pytest.raises(EctskinError, match=r"field 'task' is 'touch', expected 'contact'"):
        from ectskin.study.fewshot import few_shot_curve

        few_shot_curve(run, new)


def test_command_options(tmp_path):
    import argparse

    p = argparse.ArgumentParser()
    fewshot_touch.add_arguments(p)
    args = p.parse_args(["RUN", str(tmp_path / "new.h5"), "-o", str(tmp_path / "o")])
    assert (args.frames, args.draws, args.methods) == (
        "0,100,300,1000",
        3,
        "finetune,scratch,logreg,knn",
    )
    bad = p.parse_args(["RUN", "new.h5", "-o", "o", "--methods", "knn,ridge"])
    with pytest.raises(EctskinError, match=r"'method'.*got 'ridge'"):
        fewshot_touch.run(bad)
    assert not (tmp_path / "o").exists()
    from ectskin.commands.study import study_modules

    assert ("few-shot-touch", fewshot_touch) in study_modules()
