"""The contact task: its data set against hand-built trials, its loss's finger matching, and a
model that learns an analytic flat-skin readout far better than the region-centre baseline."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ectskin.learn.baselines.contact import region_centre_baseline
from ectskin.learn.data.contact import MAX_FINGERS, contact_dataset
from ectskin.learn.models.contact import ContactNet, ContactNetConfig
from ectskin.learn.tasks import get_task
from ectskin.learn.tasks.contact import ContactCriterion, contact_report
from ectskin.learn.train import TrainConfig, train


def test_dataset_targets_by_hand(layout, contact_recording):
    rec = contact_recording(layout, n_frames=5, n_trials=2)
    # make trial touch_0 lift at frame 3 to 4 mm (hover) and frame 4 to 40 mm (not hover)
    t = rec.trials[1]
    t.contact[3:] = False
    t.finger_uv_mm[3:] = np.nan
    t.finger_height_mm[3:, 0] = [4.0, 40.0]  # (finger 0 of the fingers axis)
    t.force[3:] = 0.0
    d = contact_dataset(rec, window=3)
    assert d.x.shape == (15, 3, layout.n_pairs)
    rows = d.group == 1
    assert d.count[rows].tolist() == [1, 1, 1, 0, 0]
    assert d.hover[rows].tolist() == [0, 0, 0, 1, 0]
    assert d.face[rows, 0].tolist() == [0, 0, 0, -1, -1]
    assert (d.face[:, 1] == -1).all() and MAX_FINGERS == 2
    np.testing.assert_allclose(d.uv[rows][0, 0], t.finger_uv_mm[0, 0])
    # the window of frame 0 is frame 0 repeated; of frame 4, frames 2, 3, 4
    np.testing.assert_array_equal(d.x[rows][0, 0], d.x[rows][0, 2])
    np.testing.assert_array_equal(d.x[rows][4, 0], d.x[rows][2, 2])


def test_the_loss_matches_two_fingers_in_either_order():
    torch.manual_seed(0)
    model = ContactNet(ContactNetConfig(n_pairs=4, window=2, n_faces=2)).eval()  # no dropout
    crit = ContactCriterion(model, thickness_mm=20.0)
    x = torch.randn(3, 2, 4)
    count = torch.tensor([2, 2, 1])
    face = torch.tensor([[0, 1], [1, 0], [0, -1]])
    uv = torch.tensor(
        [[[1.0, 2.0], [3.0, 40.0]], [[5.0, 6.0], [-7.0, 80.0]], [[0.0, 10.0], [0.0, 0.0]]]
    )
    force = torch.tensor([[1.0, 0.5], [0.7, 1.2], [0.9, 0.0]])
    hover = torch.zeros(3)
    swap = torch.tensor([1, 0])
    a, _ = crit._per_sample(model, (x, count, face, uv, force, hover))
    b, _ = crit._per_sample(model, (x, count, face[:, swap], uv[:, swap], force[:, swap], hover))
    torch.testing.assert_close(a[:2], b[:2])  # two fingers: the order does not matter
    assert not torch.allclose(a[2], b[2])  # one finger is slot 0, the empty slot is not a finger


def test_contact_model_learns_a_flat_skin_better_than_region_centres(
    layout, tmp_path, contact_recording
):
    rec = contact_recording(layout, n_frames=40, n_trials=60)
    task = get_task("contact")
    d = task.dataset(rec, window=2)
    groups = np.arange(d.n_groups)
    tr, va, te = d.select(groups[:-12]), d.select(groups[-12:-6]), d.select(groups[-6:])
    train(
        "contact",
        tr,
        va,
        tmp_path / "run",
        TrainConfig(profile="quick", seed=0, epochs=12, progress=False),
    )
    from ectskin.learn.checkpoint import load_checkpoint

    model, _, _ = load_checkpoint(tmp_path / "run" / "model.pt", kind="contact_net")
    m = contact_report(te, task.predict(model, te), with_maps=False)
    base = contact_report(te, region_centre_baseline(tr, te, tr.region_centre), with_maps=False)
    # the readout is a smooth function of (u, v): a regression of it beats "the region's centre"
    assert m["loc_mm_mean"] < 0.6 * base["loc_mm_mean"]
    assert m["face_accuracy"] == pytest.approx(1.0)
    assert m["count_accuracy"] == pytest.approx(1.0)


def test_count_weights_by_hand():
    from ectskin.learn.tasks.contact import count_weights

    # 90 frames without a finger, 9 with one, 1 with two: n / (3 n_c) = 1/2.7, 10/2.7, 100/3
    w = count_weights(np.array([0] * 90 + [1] * 9 + [2]))
    np.testing.assert_allclose(w.numpy(), np.sqrt([100 / 270, 100 / 27, 100 / 3]), rtol=1e-6)
    # a count the data lacks weighs 1 and does not change the others' ratio
    w = count_weights(np.array([0, 0, 1, 1]))
    np.testing.assert_allclose(w.numpy(), [1.0, 1.0, 1.0])
