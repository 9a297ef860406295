"""Training refuses data no model can learn from, and seeds numpy cannot take: one check for
every touch model (``TouchTask.check_trainable``), before any is built."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.io import write_recording
from ectskin.learn.train import TrainConfig, train, train_from_recording

ONE_CLASS = r"the training frames hold one touch class \(class 0, no touch\); a touch model"


@pytest.fixture
def rest_only(tmp_path, make_recording):
    """Three inflation states, each with its no-contact trial and no touch trial (what
    ``ectskin simulate --touch-trials 0`` records)."""
    path = tmp_path / "rest.h5"
    states = ((0.0, 0.0, 0.0), (20.0, 0.0, 10.0), (10.0, 10.0, 10.0))
    write_recording(make_recording(n_frames=20, states=states, regions=()), path)
    return path


@pytest.mark.parametrize("model", ["mlp", "auto", "logreg", "gbt"])
def test_every_touch_model_refuses_one_class_with_the_same_message(tmp_path, rest_only, model):
    """Defect 3: the TouchMLP trained on a recording of one class and evaluate reported
    100.00 %, while logreg / gbt / auto refused it (auto only after training the MLP). Now one
    check, before anything is trained or written. Catches a check on the classical path only."""
    out = tmp_path / model
    config = TrainConfig(profile="quick", epochs=1, counts=(1, 1, 1), progress=False, model=model)
    with pytest.raises(EctskinError, match=rf"rest.h5: {ONE_CLASS}") as exc:
        train_from_recording("touch", rest_only, out, config)
    assert "(any --model: mlp, auto or a classical one)" in str(exc.value)
    assert not out.exists()


def test_train_refuses_a_one_class_training_split(tmp_path, blobs):
    """The same check on the in-memory API (``train`` with TouchData splits)."""
    data = blobs(6, 10, seed=0)
    only0 = data.select(np.flatnonzero(np.arange(6) % 5 == 0))
    with pytest.raises(EctskinError, match=rf"train_data: {ONE_CLASS}"):
        train("touch", only0, data, tmp_path / "run", TrainConfig(progress=False))
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("field, value", [("seed", -1), ("seed", 2**32), ("split_seed", -5)])
def test_a_seed_numpy_cannot_take_is_refused_at_the_door(tmp_path, rest_only, field, value):
    """Defect 1 (the API behind ``train --seed``): a negative seed reached numpy's generator
    as a traceback after the data was read."""
    config = TrainConfig(progress=False, **{field: value})
    with pytest.raises(EctskinError, match=rf"TrainConfig: {field} must be an integer from 0"):
        train_from_recording("touch", rest_only, tmp_path / "run", config)
