"""The ONNX Runtime path for single frames (ectskin.learn.runtime): the export answers what the
PyTorch model answers on inputs it was not checked on, batches stay on PyTorch, and an export
that does not reproduce its model is refused."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ectskin._check import EctskinError
from ectskin.learn.checkpoint import save_checkpoint
from ectskin.learn.models.contact import ContactNet, ContactNetConfig
from ectskin.learn.predict import ContactPredictor, TouchPredictor, TrackPredictor
from ectskin.learn.runtime import OnnxModel

TOL = {"rtol": 1e-4, "atol": 1e-4}


def _inputs(pred, rng):
    """One random single-frame input per model input, at the scale of calibrated readouts
    (and, for a tracking model with prior, marker coordinates of tens of mm)."""
    shapes = pred._single_shapes()
    args = [rng.normal(size=shapes[0][1:]) * 0.3]
    if len(shapes) > 1:
        args.append(rng.normal(size=shapes[1][1:]) * 40)
    return args


@pytest.mark.parametrize("kind", ["touch", "track", "track_no_prior", "contact"])
def test_onnx_predictor_answers_as_pytorch(
    tmp_path, kind, make_c2dt, make_touch_mlp, randomise_head
):
    torch.manual_seed(3)
    if kind == "touch":
        model, cls = make_touch_mlp(), TouchPredictor
    elif kind == "contact":
        model, cls = ContactNet(ContactNetConfig(n_pairs=28, window=4, hidden=32)), ContactPredictor
    else:
        model, cls = make_c2dt(prior=kind == "track").eval(), TrackPredictor
        randomise_head(model)  # an untrained C2DT's head is zero: its output would not test much
    save_checkpoint(tmp_path / "model.pt", model)
    eager = cls.from_run(tmp_path)
    fast = cls.from_run(tmp_path).use_runtime("onnx")
    assert (eager.runtime, fast.runtime) == ("torch", "onnx")
    rng = np.random.default_rng(11)  # not the export check's inputs (a torch generator, seed 0)
    for _ in range(5):
        args = _inputs(fast, rng)
        want = eager.predict(*args)
        np.testing.assert_allclose(fast.predict(*args), want, **TOL)
        assert np.ptp(want) > 1e-3  # the comparison is not between two constants
    # a batch is PyTorch's own, to the last bit
    batch = [np.stack([a, a * 0.5]) for a in _inputs(fast, rng)]
    np.testing.assert_array_equal(fast.predict(*batch), eager.predict(*batch))
    # back to torch
    args = _inputs(fast, rng)
    np.testing.assert_array_equal(fast.use_runtime("torch").predict(*args), eager.predict(*args))


def test_contact_reading_through_onnx_keeps_count_and_faces(tmp_path):
    torch.manual_seed(5)
    net = ContactNet(ContactNetConfig(n_pairs=28, window=3, hidden=16, channels=8))
    save_checkpoint(tmp_path / "model.pt", net)
    eager = ContactPredictor.from_run(tmp_path)
    fast = ContactPredictor.from_run(tmp_path).use_runtime("onnx")
    rng = np.random.default_rng(2)
    counts = set()
    for _ in range(20):
        w = rng.normal(size=(3, 28)) * rng.choice([0.01, 1.0, 5.0])
        a, b = eager.read(w), fast.read(w)
        counts.add(a.count)
        assert (b.count, [f.face for f in b.fingers]) == (a.count, [f.face for f in a.fingers])
        assert b.p_contact == pytest.approx(a.p_contact, abs=1e-4)


class _ExportsOtherwise(torch.nn.Module):
    """A model whose Python branch the export sees differently from eager calls."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + 1.0 if torch.compiler.is_exporting() else x


def test_an_export_that_does_not_reproduce_its_model_is_refused():
    with pytest.raises(EctskinError, match=r"odd: the ONNX export does not reproduce .* 1\.0"):
        OnnxModel(_ExportsOtherwise(), [(1, 4)], name="odd")


def test_wrong_input_shape_and_unknown_runtime(tmp_path, make_touch_mlp):
    m = OnnxModel(torch.nn.Linear(4, 2), [(1, 4)], name="lin")
    with pytest.raises(
        EctskinError, match=r"lin \(ONNX\): input x0 must have shape \(1, 4\), got \(1, 3\)"
    ):
        m(np.zeros((1, 3)))
    save_checkpoint(tmp_path / "model.pt", make_touch_mlp())
    with pytest.raises(EctskinError, match="runtime must be one of"):
        TouchPredictor.from_run(tmp_path).use_runtime("tensorrt")
