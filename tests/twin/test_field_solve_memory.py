"""The node solves' process keeps the memory it frees (``field_solve.keep_freed_memory``):
glibc takes both settings, once per process; without a C library to ask, the helper says so
and the solves go on (they are the same numbers either way)."""

from __future__ import annotations

import platform

import pytest

from ectskin.twin import field_solve


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_glibc_keeps_the_solves_freed_memory(monkeypatch):
    monkeypatch.setattr(field_solve, "_MALLOC_SET", [])
    assert field_solve.keep_freed_memory() is True
    calls = []
    monkeypatch.setattr(field_solve.ctypes, "CDLL", lambda *a: calls.append(a))
    assert field_solve.keep_freed_memory() is True and not calls  # remembered, not asked again


def test_without_a_c_library_the_solves_go_on(monkeypatch):
    def missing(*a):
        raise OSError("no libc here")

    monkeypatch.setattr(field_solve, "_MALLOC_SET", [])
    monkeypatch.setattr(field_solve.ctypes, "CDLL", missing)
    assert field_solve.keep_freed_memory() is False
