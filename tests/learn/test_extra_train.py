"""Trials that join a run's training split only (TrainConfig.extra_train)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.learn.extra_train import join_training
from ectskin.learn.profiles import TrainConfig, describe_recipe
from ectskin.learn.splits import trial_digests
from ectskin.learn.tasks import get_task
from ectskin.learn.train import train_from_recording

REGIONS = (1, 5, 10, 14)


@pytest.fixture
def files(tmp_path, make_recording):
    main, extra = tmp_path / "data.h5", tmp_path / "extra.h5"
    write_recording(make_recording(n_frames=40, regions=REGIONS, occluded=(), no_markers=()), main)
    # another session of the skin: other readouts (seed), shorter trials
    write_recording(
        make_recording(n_frames=20, seed=1, regions=REGIONS, occluded=(), no_markers=()), extra
    )
    return main, extra


def test_extra_trials_join_the_training_split_alone(tmp_path, files):
    main, extra = files
    config = TrainConfig(profile="robust", epochs=2, counts=(6, 2, 2), progress=False)
    plain = train_from_recording("touch", main, tmp_path / "plain", config)
    joined = train_from_recording(
        "touch", main, tmp_path / "joined", replace(config, extra_train=(str(extra),))
    )
    a, b = (json.loads((tmp_path / r / "split.json").read_text()) for r in ("plain", "joined"))
    # the run's own split is the same trial for trial: validation and test mean what they meant
    assert [a[k] for k in ("train", "val", "test")] == [b[k] for k in ("train", "val", "test")]
    assert (plain["n_val"], plain["n_test"]) == (joined["n_val"], joined["n_test"])
    # every extra trial (2 states x (rest + 4 regions) of 20 frames) joined the training samples
    assert joined["n_train"] == plain["n_train"] + 10 * 20
    (item,) = b["extra_train"]
    assert item["file"] == str(extra.resolve())
    assert item["trial_digests"] == trial_digests(read_recording(extra))
    recipe = json.loads((tmp_path / "joined" / "config.json").read_text())["recipe"]
    assert recipe["extra_train"] == [{"file": "extra.h5", "trials": 10}]
    assert "10 extra training trials of extra.h5" in describe_recipe(recipe)
    assert "extra_train" not in a and "extra" not in describe_recipe(
        json.loads((tmp_path / "plain" / "config.json").read_text())["recipe"]
    )


def test_extra_data_of_another_skin_or_no_file_is_refused(tmp_path, files, make_recording):
    main, extra = files
    task = get_task("touch")
    train = task.dataset(read_recording(main), reference="state-offset")
    other = replace(train, pair_names=[f"x{i}" for i in range(train.n_pairs)])
    with pytest.raises(EctskinError, match=r"other\.h5: its pair_names differ"):
        join_training(train, [other], ["other.h5"])
    config = TrainConfig(profile="robust", epochs=1, counts=(6, 2, 2), progress=False,
                         extra_train=(str(tmp_path / "nope.h5"),))
    with pytest.raises(EctskinError, match="nope.h5"):
        train_from_recording("touch", main, tmp_path / "run", config)
    # the run's own recording as extra data would put its validation and test trials in training
    same = replace(config, extra_train=(str(main),))
    with pytest.raises(EctskinError, match=r"data\.h5: 10 trial\(s\) .* of the run's own"):
        train_from_recording("touch", main, tmp_path / "run2", same)
    assert not (tmp_path / "run2" / "model.pt").exists()


@pytest.fixture
def fitted(monkeypatch):
    """The training sample counts the touch baselines are fitted on, call by call."""
    from ectskin.learn.tasks.touch import TouchTask

    counts: list[int] = []
    real = TouchTask.baseline_metrics

    def spy(self, train, test, **kw):
        counts.append(train.n_samples)
        return real(self, train, test, **kw)

    monkeypatch.setattr(TouchTask, "baseline_metrics", spy)
    return counts


def test_the_baselines_are_fitted_on_the_run_s_extra_trials_too(tmp_path, files, fitted):
    from ectskin.learn.evaluate import evaluate_run

    main, extra = files
    config = TrainConfig(profile="robust", epochs=1, counts=(6, 2, 2), progress=False,
                         extra_train=(str(extra),))
    train_from_recording("touch", main, tmp_path / "run", config)
    m = evaluate_run(tmp_path / "run", main, figures=False, write=False)["touch"]
    assert fitted == [6 * 40 + 10 * 20] and m["baselines"]
    # the extra recording changed since training: no baselines, and the reason said
    write_recording(read_recording(main), extra, overwrite=True)
    m = evaluate_run(tmp_path / "run", main, figures=False, write=False)["touch"]
    assert not m["baselines"] and "extra.h5 changed since training" in m["baselines_skipped"]


def test_a_moved_folder_keeps_its_baselines_on_the_extra_trials(tmp_path, files, fitted):
    """A reproduction's folder moved whole (coverage.h5 beside runs/): the extra recording is
    found by name near the run and checked by its trial digests. Catches the stored absolute
    path alone (baselines skipped after any move) and a same-named file taken unchecked."""
    import shutil

    from ectskin.learn.evaluate import evaluate_run

    main, extra = files
    old = tmp_path / "old"
    (old / "runs").mkdir(parents=True)
    shutil.copy(extra, old / "coverage.h5")
    config = TrainConfig(profile="robust", epochs=1, counts=(6, 2, 2), progress=False,
                         extra_train=(str(old / "coverage.h5"),))
    train_from_recording("touch", main, old / "runs" / "touch", config)
    new = tmp_path / "new"
    old.rename(new)
    m = evaluate_run(new / "runs" / "touch", main, figures=False, write=False)["touch"]
    assert fitted == [6 * 40 + 10 * 20] and m["baselines"]
    # another recording of that name near the run is not taken for it
    write_recording(read_recording(main), new / "coverage.h5", overwrite=True)
    m = evaluate_run(new / "runs" / "touch", main, figures=False, write=False)["touch"]
    assert not m["baselines"] and "changed since training" in m["baselines_skipped"]


def _with_states(rec, states):
    """``rec`` with its touch trials put at ``states`` in turn (the rest trial stays at rest)."""
    trials = [t if i == 0 else replace(t, inflation=states[i % len(states)])
              for i, t in enumerate(rec.trials)]
    return replace(rec, trials=trials)


def test_a_contact_extra_of_some_of_the_run_s_states_joins_with_their_indices(contact_recording):
    """An extra contact recording made at some of the run's inflation states (another order)
    joins with each sample's state index pointing at its own state in the run's list; one with a
    state the run lacks is refused, naming the file and the state."""
    task = get_task("contact")
    states = [(0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 20.0, 0.0), (0.0, 0.0, 20.0)]
    run = _with_states(contact_recording(n_frames=12, n_trials=8, seed=0), states)
    extra = _with_states(contact_recording(n_frames=12, n_trials=6, seed=1),
                         [(0.0, 0.0, 0.0), (0.0, 0.0, 20.0), (20.0, 0.0, 0.0)])
    train = task.dataset(run, window=1)
    more = task.dataset(extra, window=1)
    assert more.states != train.states  # a subset, in another order
    joined = join_training(train, [more], ["extra.h5"])
    assert joined.states == train.states
    tail = joined.state[train.n_samples:]
    truth = [extra.trial(n.split("/", 1)[1]).inflation
             for n in np.asarray(joined.group_names)[joined.group[train.n_samples:]]]
    assert [train.states[i] for i in tail] == truth
    other = task.dataset(_with_states(extra, [(0.0, 0.0, 0.0), (10.0, 10.0, 10.0)]), window=1)
    with pytest.raises(EctskinError, match=r"odd\.h5: inflation state\(s\) \[\[10\.0, 10\.0, 10\.0\]\]"):
        join_training(train, [other], ["odd.h5"])
