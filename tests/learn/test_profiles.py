"""Training profiles (ectskin.learn.profiles): the paper's settings, the robust recipe, checks."""

from __future__ import annotations

import pytest

from ectskin._check import EctskinError
from ectskin.learn.profiles import PROFILES, describe_recipe, profile_settings
from ectskin.learn.train import TrainConfig, train


def test_paper_profile_is_the_papers_settings(blobs):
    touch, track = PROFILES["paper"]["touch"], PROFILES["paper"]["track"]
    assert (touch.epochs, touch.batch_size, track.epochs, track.batch_size) == (100, 256, 150, 255)
    for s in (touch, track):
        assert (s.lr, s.step_size, s.gamma) == (1e-3, 15, 1 / 1.2)
        assert s.samples_per_epoch is None and s.val_samples is None
    assert profile_settings("touch", "quick", epochs=3).epochs == 3
    assert profile_settings("track", "quick", samples_per_epoch=None).samples_per_epoch is None
    with pytest.raises(EctskinError, match="'epochs' must be a positive integer, got 0"):
        train("touch", blobs(2, 5, seed=0), blobs(1, 5, seed=1), "unused", TrainConfig(epochs=0))
    with pytest.raises(
        EctskinError, match="allowed values are 'paper', 'quick', 'robust'; got 'fast'"
    ):
        profile_settings("touch", "fast")
    with pytest.raises(EctskinError, match="'batch_size' must be a positive integer"):
        profile_settings("touch", "paper", batch_size=0)
    with pytest.raises(EctskinError, match="unknown training setting"):
        profile_settings("touch", "paper", momentum=0.9)
    with pytest.raises(EctskinError, match="allowed values are 'touch', 'track', 'contact'; got 'shape'"):
        profile_settings("shape")


def test_robust_profile_settings_and_track_refusal(tmp_path):
    s = PROFILES["robust"]["touch"]
    assert (s.epochs, s.batch_size, s.lr, s.step_size, s.gamma) == (20, 256, 1e-3, 5, 1 / 1.2)
    assert (s.inflation_shift, s.mixup_alpha, s.label_smoothing, s.select, s.channel_gain) == (
        True,
        1.0,
        0.1,
        "val_metric",
        0.1,
    )
    for name in ("paper", "quick"):  # the paper's recipe: no augmentation, lowest val loss
        for task in ("touch", "track"):
            t = PROFILES[name][task]
            assert (t.inflation_shift, t.mixup_alpha, t.label_smoothing, t.select) == (
                False,
                0.0,
                0.0,
                "val_loss",
            )
            assert t.channel_gain == 0.0 and not t.augments
        # contact (ours, not the paper's): the inflation shift only, the best localisation kept
        c = PROFILES[name]["contact"]
        assert (c.inflation_shift, c.mixup_alpha, c.label_smoothing, c.select) == (
            True,
            0.0,
            0.0,
            "val_metric",
        )
    msg = (
        r"profile 'robust' has no settings for task 'track'.*profiles for 'track': 'paper', 'quick'"
    )
    with pytest.raises(EctskinError, match=msg):
        profile_settings("track", "robust")
    with pytest.raises(EctskinError, match=msg):
        train("track", None, None, tmp_path, TrainConfig(profile="robust"))
    with pytest.raises(EctskinError, match="apply to task 'touch' only"):
        profile_settings("track", "quick", mixup_alpha=0.2)
    with pytest.raises(EctskinError, match="'label_smoothing' must be in"):
        profile_settings("touch", "robust", label_smoothing=1.0)
    with pytest.raises(EctskinError, match="'mixup_alpha' must be >= 0"):
        profile_settings("touch", "robust", mixup_alpha=-1)
    with pytest.raises(EctskinError, match="allowed values are 'val_loss', 'val_metric'"):
        profile_settings("touch", "robust", select="best")
    with pytest.raises(EctskinError, match="'channel_gain' must be >= 0"):
        profile_settings("touch", "robust", channel_gain=-0.1)
    with pytest.raises(EctskinError, match="'channel_gain' apply to task 'touch' only"):
        profile_settings("contact", "quick", channel_gain=0.1)


def test_cli_refuses_robust_for_track_naming_the_profiles(tmp_path, capsys, cli, make_recording):
    from ectskin.io import write_recording

    path = tmp_path / "data.h5"
    write_recording(make_recording(n_frames=10), path)
    argv = ["train", "track", str(path), "--out", str(tmp_path / "run"), "--profile", "robust"]
    assert cli(argv) == 2
    err = capsys.readouterr().err
    assert "profile 'robust' has no settings for task 'track'" in err
    assert "'paper', 'quick'" in err
    assert not (tmp_path / "run").exists()


def test_describe_recipe():
    assert describe_recipe(None) == describe_recipe({}) == "the paper's recipe"
    recipe = {
        "inflation_shift": True,
        "inflation_shift_states": 25,
        "mixup_alpha": 0.4,
        "label_smoothing": 0.1,
        "select": "val_metric",
    }
    assert describe_recipe(recipe) == (
        "inflation shift over 25 no-contact training states, mixup (Beta 0.4, 0.4), label "
        "smoothing 0.1, weights of the best validation accuracy"
    )
    assert describe_recipe({**recipe, "channel_gain": 0.1}) == (
        "inflation shift over 25 no-contact training states, mixup (Beta 0.4, 0.4), a gain per "
        "channel (log-normal, sigma 0.1), label smoothing 0.1, weights of the best validation "
        "accuracy"
    )
    skipped = {**recipe, "inflation_shift_states": 0, "mixup_alpha": 0, "select": "val_loss"}
    assert describe_recipe(skipped) == (
        "inflation shift skipped (fewer than 2 no-contact training trials), label smoothing 0.1, "
        "weights of the lowest validation loss"
    )


def test_the_finger_mix_is_a_contact_probability_off_by_default():
    assert all(s.finger_mix == 0 for per_task in PROFILES.values() for s in per_task.values())
    assert profile_settings("contact", "quick", finger_mix=0.25).finger_mix == 0.25
    with pytest.raises(EctskinError, match="'finger_mix' applies to task 'contact' only"):
        profile_settings("touch", "quick", finger_mix=0.25)
    with pytest.raises(EctskinError, match="'finger_mix' must be a probability from 0 to 1"):
        profile_settings("contact", "quick", finger_mix=1.5)
