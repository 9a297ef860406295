"""The code that made each cached step (``ectskin.pipeline.runner.code_version``).

Checked against a git repository built here (its commit from ``git rev-parse``, a changed
file, a folder outside any checkout), and through :class:`StepRunner`: a step that other code
made is reused with a warning that names both codes, and the state records who made it.
"""

from __future__ import annotations

import json
import logging
import subprocess

from ectskin import __version__
from ectskin.pipeline import runner
from ectskin.pipeline.runner import StepRunner, code_version


def _git(where, *args):
    return subprocess.run(["git", "-C", str(where), *args], capture_output=True, text=True,
                          check=True).stdout.strip()


def test_code_version_is_the_checkouts_commit_and_its_changes(tmp_path):
    repo = tmp_path / "repo"
    pkg = repo / "pkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("x = 1\n")
    _git(repo, "init", "-q")
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "one")
    head = _git(repo, "rev-parse", "--short=12", "HEAD")
    assert code_version(pkg) == head and len(head) == 12
    (pkg / "__init__.py").write_text("x = 2\n")  # uncommitted: the commit and a hash of it
    code_version.cache_clear()
    changed = code_version(pkg)
    assert changed.startswith(head + "+") and len(changed) == 12 + 1 + 8
    (pkg / "__init__.py").write_text("x = 3\n")  # another change, another hash
    code_version.cache_clear()
    assert code_version(pkg) not in (head, changed)
    # a folder no checkout tracks (an installed copy): the package's version
    copy = tmp_path / "site" / "pkg"
    copy.mkdir(parents=True)
    (copy / "__init__.py").write_text("x = 1\n")
    assert code_version(copy) == f"ectskin {__version__}"
    code_version.cache_clear()


def test_a_step_other_code_made_is_reused_with_a_warning(tmp_path, monkeypatch, caplog):
    target = tmp_path / "a.txt"

    def write(text):
        return lambda: target.write_text(text) and text

    monkeypatch.setattr(runner, "code_version", lambda: "aaaaaaaaaaaa")
    assert StepRunner(tmp_path, force=False).step("a", {"x": 1}, [target], write("one")) == "one"
    state = json.loads((tmp_path / "reproduce.json").read_text())["steps"]["a"]
    assert state["code"] == "aaaaaaaaaaaa" and state["done"]
    with caplog.at_level(logging.INFO, logger="ectskin.pipeline.runner"):
        assert StepRunner(tmp_path, force=False).step("a", {"x": 1}, [target], write("b")) is None
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]  # the same code
    monkeypatch.setattr(runner, "code_version", lambda: "bbbbbbbbbbbb+0123abcd")
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="ectskin.pipeline.runner"):
        again = StepRunner(tmp_path, force=False)
        assert again.step("a", {"x": 1}, [target], write("two")) is None
    assert again.reused == ["a"] and target.read_text() == "one"  # reused, not redone
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 1
    assert "made by other code (aaaaaaaaaaaa; this is bbbbbbbbbbbb+0123abcd)" in warned[0]
    assert "remove a.txt (or use another output folder) to redo it" in warned[0]
