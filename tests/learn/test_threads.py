"""The one torch thread policy (learn/threads.py)."""

import os

import pytest
import torch

from ectskin._check import EctskinError
from ectskin.learn.threads import resolve_threads, torch_threads


def test_resolve_threads(monkeypatch):
    assert resolve_threads(3) == 3 and resolve_threads(None) is None
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert resolve_threads("auto") == 1
    monkeypatch.setattr(os, "cpu_count", lambda: 16)
    assert resolve_threads("auto") is None
    with pytest.raises(EctskinError, match="threads must be"):
        resolve_threads(0)


def test_torch_threads_sets_and_restores():
    before = torch.get_num_threads()
    with torch_threads(2) as n:
        assert n == 2 == torch.get_num_threads()
    assert torch.get_num_threads() == before
    with torch_threads(None) as n:
        assert n == before
