"""``ectskin live --contact-model RUN --ect --ect-every N``: the heads reach the engine, every JSON
line carries the contact reading (the model's own, recomputed here from the frames), the image
comes every N-th frame, and the recording names the contact model."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from ectskin.cli import main
from ectskin.commands import live as live_cmd
from ectskin.io.hdf5 import read_recording, write_recording
from ectskin.io.recording import Recording, Trial
from ectskin.layout import default_layout
from ectskin.learn.checkpoint import save_checkpoint
from ectskin.learn.models.contact import ContactNet, ContactNetConfig
from ectskin.learn.predict import ContactPredictor

LAYOUT = default_layout()
P = LAYOUT.n_pairs
EXTENT = {"front": [[-20.0, 20.0], [5.0, 115.0]], "back": [[-20.0, 20.0], [5.0, 115.0]]}


class GridImager:
    """ECT imager protocol: a 2 x 3 image per face from the first 12 values of delta_c."""

    faces = ["front", "back"]
    grid_extent = EXTENT

    def image(self, dc):
        return {"front": dc[:6].reshape(2, 3), "back": dc[6:12].reshape(2, 3)}

    def locate(self, dc):
        return "back", 1.0, 2.0, float(dc[6:12].max())


def _same_reading(got: dict, want: dict, exact: bool) -> None:
    """``exact``: equal to the last bit (the PyTorch runtime is the offline predictor itself);
    else the same count and faces, numbers to 1e-4 (ONNX Runtime's float32 kernels)."""
    if exact:
        assert got == want
        return
    assert got["count"] == want["count"]
    assert [f["face"] for f in got["fingers"]] == [f["face"] for f in want["fingers"]]

    def flat(r):
        keys = ("u_mm", "v_mm", "sigma_mm", "force_n")
        return [r["p_contact"], r["p_hover"]] + [f[k] for f in r["fingers"] for k in keys]

    np.testing.assert_allclose(flat(got), flat(want), rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("runtime", ["torch", "onnx"])
def test_cli_live_with_contact_model_and_ect(tmp_path, capsys, monkeypatch, runtime):
    n, k, ref = 40, 3, 10
    cap = 10 + np.random.default_rng(8).random((n, P))
    src = write_recording(
        Recording(LAYOUT, [Trial("t", cap, np.arange(n) / 30.0, np.zeros(n))], 30.0),
        tmp_path / "in.h5",
    )
    torch.manual_seed(0)
    net = ContactNet(ContactNetConfig(n_pairs=P, window=k, hidden=16, channels=8))
    extra = {
        "pair_names": list(LAYOUT.pair_names),
        "faces": ["front", "back"],
        "face_extent": EXTENT,
    }
    save_checkpoint(tmp_path / "contact" / "model.pt", net, extra=extra)
    monkeypatch.setattr(live_cmd, "_ect_imager", lambda layout: GridImager())
    jsonl, rec = tmp_path / "out.jsonl", tmp_path / "live.h5"
    argv = [
        "live",
        "--source",
        f"replay:{src}",
        "--speed",
        "inf",
        "--policy",
        "block",
        "--contact-model",
        str(tmp_path / "contact"),
        "--ect",
        "--ect-every",
        "4",
        "--reference-frames",
        str(ref),
        "--jsonl",
        str(jsonl),
        "--record",
        str(rec),
        "--threads",
        str(torch.get_num_threads()),
        "--runtime",
        runtime,
    ]
    assert main(argv) == 0
    lines = [json.loads(x) for x in jsonl.read_text().splitlines()]
    assert [m["seq"] for m in lines] == list(range(n))
    assert all(m["contact"] is None and m["ect"] is None for m in lines[: ref - 1])
    # every frame from the reference on: the model's reading of the Eq. 2 window
    predictor = ContactPredictor.from_run(tmp_path / "contact")
    c0 = cap[:ref].mean(0)
    for i in range(ref - 1, n):
        w = ((cap[i - k + 1 : i + 1] - c0) / c0).astype(np.float32)
        _same_reading(lines[i]["contact"], predictor.read(w).to_dict(), runtime == "torch")
    imaged = [m["seq"] for m in lines if m["ect"] is not None]
    assert imaged == list(range(ref - 1, n, 4))
    last = lines[imaged[-1]]["ect"]
    assert (last["face"], last["u_mm"], last["v_mm"]) == ("back", 1.0, 2.0)
    img = last["image"]
    dc = cap[imaged[-1]] - c0
    np.testing.assert_allclose(
        np.asarray(img["faces"]["back"]) * img["scale"] / img["levels"],
        dc[6:12].reshape(2, 3),
        atol=img["scale"] / img["levels"],
    )
    assert read_recording(rec).n_frames == n
    meta = read_recording(rec).meta
    assert meta["contact_model"] == str(tmp_path / "contact") and meta["ect_every"] == 4
    assert meta["runtime"] == runtime
    err = capsys.readouterr().err
    assert "final (the source ended): frames 40, processed 40, dropped 0" in err
    assert ("answers with ONNX Runtime" in err) == (runtime == "onnx")


def test_cli_ect_every_must_be_positive(capsys):
    assert main(["live", "--source", "sim", "--ect", "--ect-every", "0"]) == 2
    assert "--ect-every must be >= 1 (frames), got 0" in capsys.readouterr().err
