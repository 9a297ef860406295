"""Distributed data parallel: ``train`` runs unchanged under ``torchrun --nproc_per_node 2``.

One torchrun launch (gloo on CPU) trains a TouchMLP and a small C2DT (and a TouchMLP with the
robust profile, whose augmentation each rank draws for its own shard). Checked: both ranks
finish, they saw disjoint halves of each epoch's permutation that together cover the training
set, only rank 0 wrote files, and — with dropout off, where 2 ranks x (batch / 2) is the same
mathematics as 1 process x batch — the weights and validation metrics match a single-process
run of the same data and seed.
"""

from __future__ import annotations

import json
import os
import pickle
import socket
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest
import torch

from ectskin._check import EctskinError
from ectskin.learn.checkpoint import load_checkpoint, read_checkpoint
from ectskin.learn.distributed import Dist
from ectskin.learn.engine import Tensors, train_one_epoch
from ectskin.learn.models import TouchMLP
from ectskin.learn.runfiles import read_metrics
from ectskin.learn.tasks import TouchCriterion
from ectskin.learn.train import TrainConfig, train

pytestmark = pytest.mark.ddp

#: What each rank runs: the three trainings on the data sets pickled by the fixture, recording
#: the epoch indices each rank saw.
SCRIPT = textwrap.dedent(
    """
    import json, os, pickle, sys, faulthandler
    faulthandler.dump_traceback_later(150, exit=True)  # a hang fails with stacks
    import torch
    torch.set_num_threads(1)
    import ectskin.learn.train as T

    out = sys.argv[1]
    with open(out + "/data.pkl", "rb") as fh:
        data, small_c2dt = pickle.load(fh)
    rank = int(os.environ["RANK"])
    seen = []
    original = T.epoch_indices

    def recording(n, epoch, seed, **kw):
        idx = original(n, epoch, seed, **kw)
        seen.append({"n": n, "epoch": epoch, **kw, "idx": idx.tolist()})
        return idx

    T.epoch_indices = recording
    result = {}
    tr, va = data["touch"]
    result["touch"] = T.train("touch", tr, va, out + "/touch", T.TrainConfig(
        profile="quick", epochs=3, batch_size=64, model_options={"dropout": 0.0}, progress=False))
    tr, va = data["track"]
    result["track"] = T.train("track", tr, va, out + "/track", T.TrainConfig(
        profile="quick", epochs=2, batch_size=32, model_options=small_c2dt, progress=False,
        settings={"samples_per_epoch": None, "val_samples": None}))
    tr, va = data["robust"]
    result["robust"] = T.train("touch", tr, va, out + "/robust", T.TrainConfig(
        profile="robust", epochs=2, batch_size=64, progress=False))
    with open(f"{out}/rank{rank}.json", "w") as fh:
        json.dump({"result": result, "seen": seen}, fh)
    """
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: how a rank aborted from C++ reads in torchrun's report (std::terminate: "terminate called
#: without an active exception", then SIGABRT; most likely gloo's threads), seen once in eight runs of
#: this module on a 2-core machine (in a full `make test-all`, none in seven runs alone); see
#: pytorch/pytorch#179291 on gloo threads at process exit
RANK_ABORT = "Signal 6 (SIGABRT)"


@pytest.fixture(scope="module")
def ddp_run(tmp_path_factory, blobs, displacements, states_data, small_c2dt):
    data = {
        "touch": (blobs(20, 30, seed=0), blobs(6, 30, seed=1)),
        "track": (displacements(4, 60, seed=0), displacements(2, 60, seed=1)),
        "robust": (states_data(0, 0, per=20), states_data(1, 0, per=20, no_contact=False)),
    }
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("WORLD_SIZE", None)
    # a launch with a rank aborted that way is run once more, in a fresh folder, and the abort is
    # reported as a warning; any other failure, or a second abort, fails the tests
    for attempt in (1, 2):
        tmp = tmp_path_factory.mktemp("ddp")
        with open(tmp / "data.pkl", "wb") as fh:
            pickle.dump((data, small_c2dt), fh)
        script = tmp / "ddp_script.py"
        script.write_text(SCRIPT)
        cmd = [
            sys.executable,
            "-m",
            "torch.distributed.run",
            "--nproc_per_node",
            "2",
            "--master_addr",
            "127.0.0.1",
            "--master_port",
            str(_free_port()),
            str(script),
            str(tmp),
        ]
        proc = subprocess.run(cmd, check=False, env=env, capture_output=True, text=True,
                              timeout=300)
        report = proc.stdout[-3000:] + proc.stderr[-3000:]
        if proc.returncode == 0 or attempt == 2 or RANK_ABORT not in proc.stderr:
            break
        warnings.warn(f"torchrun: a rank aborted (SIGABRT); launched again:\n{report}",
                      stacklevel=1)
    assert proc.returncode == 0, report
    ranks = [json.loads((tmp / f"rank{r}.json").read_text()) for r in (0, 1)]
    return tmp, ranks


def test_ranks_saw_disjoint_shards_covering_the_epoch(ddp_run):
    _, ranks = ddp_run
    for task_n, epochs in ((600, 3), (240, 2)):  # touch then track training sets
        for epoch in range(epochs):
            shards = [
                [s for s in r["seen"] if s["n"] == task_n and s["epoch"] == epoch] for r in ranks
            ]
            assert all(len(s) == 1 for s in shards)
            a, b = (s[0] for s in shards)
            assert (a["rank"], b["rank"], a["world_size"], b["world_size"]) == (0, 1, 2, 2)
            assert len(a["idx"]) == len(b["idx"]) == task_n // 2
            assert not set(a["idx"]) & set(b["idx"])
            assert set(a["idx"]) | set(b["idx"]) == set(range(task_n))
    for r in ranks:
        assert r["result"]["touch"]["world_size"] == 2


def test_only_rank0_wrote_and_the_model_is_good(ddp_run, blobs):
    tmp, ranks = ddp_run
    assert sorted(p.name for p in (tmp / "touch").iterdir()) == [
        "config.json",
        "last.pt",
        "metrics.csv",
        "model.pt",
        "split.json",
    ]
    assert not list(tmp.glob("**/.*.tmp-*"))
    model, _, payload = load_checkpoint(tmp / "touch" / "model.pt")
    assert payload["extra"]["world_size"] == 2
    te = blobs(10, 30, seed=2)
    with torch.no_grad():
        acc = (model(torch.from_numpy(te.x)).argmax(1).numpy() == te.y).mean()
    assert acc > 0.97
    # every rank returns the same all-reduced summary
    assert (
        ranks[0]["result"]["touch"]["best_val_loss"] == ranks[1]["result"]["touch"]["best_val_loss"]
    )


def test_robust_profile_trains_under_ddp(ddp_run):
    tmp, ranks = ddp_run
    results = [r["result"]["robust"] for r in ranks]
    assert [r["world_size"] for r in results] == [2, 2] and results[0]["epochs_run"] == 2
    assert results[0]["best_val_metric"] == results[1]["best_val_metric"]  # all-reduced
    cfg = json.loads((tmp / "robust" / "config.json").read_text())
    assert cfg["recipe"]["inflation_shift_states"] == 6 and cfg["batch_per_rank"] == 32
    assert sorted(p.name for p in (tmp / "robust").iterdir()) == [
        "config.json",
        "last.pt",
        "metrics.csv",
        "model.pt",
        "split.json",
    ]


def test_ddp_matches_a_single_process_run(ddp_run, tmp_path, blobs, displacements, small_c2dt):
    tmp, _ = ddp_run
    tr, va = blobs(20, 30, seed=0), blobs(6, 30, seed=1)
    train(
        "touch",
        tr,
        va,
        tmp_path / "touch",
        TrainConfig(
            profile="quick", epochs=3, batch_size=64, model_options={"dropout": 0.0}, progress=False
        ),
    )
    tr, va = displacements(4, 60, seed=0), displacements(2, 60, seed=1)
    train(
        "track",
        tr,
        va,
        tmp_path / "track",
        TrainConfig(
            profile="quick",
            epochs=2,
            batch_size=32,
            model_options=small_c2dt,
            progress=False,
            settings={"samples_per_epoch": None, "val_samples": None},
        ),
    )
    for task in ("touch", "track"):
        single = read_checkpoint(tmp_path / task / "last.pt")["state_dict"]
        ddp = read_checkpoint(tmp / task / "last.pt")["state_dict"]
        for k in single:
            torch.testing.assert_close(ddp[k], single[k], atol=1e-4, rtol=1e-4, msg=f"{task} {k}")
        m1, m2 = (
            read_metrics(tmp_path / task / "metrics.csv"),
            read_metrics(tmp / task / "metrics.csv"),
        )
        np.testing.assert_allclose(
            [r["val_loss"] for r in m2], [r["val_loss"] for r in m1], rtol=1e-4
        )


def test_deferred_non_finite_check_names_the_first_bad_batch(tmp_path):
    """Under DDP (and on CUDA) the loss is not synced every batch; the first non-finite batch is
    remembered on the device and reported after the epoch, the same on every rank."""
    import torch.distributed as dist

    dist.init_process_group("gloo", init_method=f"file://{tmp_path}/pg", rank=0, world_size=1)
    try:
        x = torch.randn(64, 28)
        x[40] = float("nan")  # sample 40 is in batch 3 of 4 (batch size 16, identity order)
        data = Tensors((x, torch.zeros(64, dtype=torch.int64)))
        model = TouchMLP()
        opt = torch.optim.Adam(model.parameters())
        d = Dist(rank=0, world_size=2)  # "distributed": take the deferred path
        with pytest.raises(EctskinError, match=r"non-finite loss at epoch 5, batch 3 of 4"):
            train_one_epoch(model, TouchCriterion(), opt, data, torch.arange(64), 16, epoch=4, d=d)
    finally:
        dist.destroy_process_group()
