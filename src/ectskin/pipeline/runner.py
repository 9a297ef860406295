"""Cached steps: run a step once, reuse it while its settings hold, refuse to overwrite otherwise.

Each step of the pipeline has a name, its *settings* (a JSON-able dict: everything its results
depend on) and its *outputs* (files or folders in the output folder). ``OUT_DIR/reproduce.json``
records per step the settings it ran with, whether it finished and how long it took::

    {"format": "ectskin.reproduce", "version": 1, "ectskin": "0.1.0",
     "steps": {"simulate": {"settings": {...}, "code": "4f8cf75a1b2c", "done": true,
                            "seconds": 27.3}, ...}}

``code`` is the code that ran the step (:func:`code_version`: the commit of the source
checkout, with a hash of the uncommitted changes to its tracked files). A step is keyed by its settings, not by the
code, so a step that other code made is still reused, with a warning that names both: a
change of the code that changes a step's results (a better fit, say) leaves its old results in
place until its outputs are removed (``--overwrite`` does not: the settings hold) or another
output folder redoes it.

:meth:`StepRunner.step` then decides:

* outputs present, step finished with the same settings → reused (listed in ``reused``);
* outputs present, step started with the same settings but not finished → run again in place
  (an interrupted training resumes from its ``last.pt``);
* outputs present but made with other settings, or of unknown origin → :class:`EctskinError`
  naming the differing settings, unless ``force`` (``--overwrite``), which removes them and runs
  the step again.

:meth:`StepRunner.steps` does the same for independent steps, running those that must run in
several processes at once (the training runs of a reproduction each use one torch thread, so on
a 2-core machine two train side by side).
"""

from __future__ import annotations

import hashlib
import json
import logging
import multiprocessing
import shutil
import subprocess
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

from ectskin import __version__
from ectskin._check import EctskinError
from ectskin._files import read_json, to_jsonable, write_json_atomic

log = logging.getLogger(__name__)

STATE_FILE = "reproduce.json"
STATE_FORMAT = "ectskin.reproduce"

T = TypeVar("T")


def plain(obj: Any) -> Any:
    """``obj`` as plain JSON values (tuples → lists ...), so settings compare equal to saved ones."""
    return json.loads(json.dumps(to_jsonable(obj), sort_keys=True))


def digest(obj: Any) -> str:
    """A short hash of ``obj``'s JSON text (16 hex digits), e.g. of a data step's settings."""
    text = json.dumps(plain(obj), sort_keys=True)
    return hashlib.blake2b(text.encode(), digest_size=8).hexdigest()


def _git(where: Path, *args: str) -> str:
    out = subprocess.run(["git", "-C", str(where), *args], capture_output=True, text=True,
                         timeout=30, check=True)
    return out.stdout


#: ectskin's package folder, whose code :func:`code_version` names
PACKAGE_DIR = Path(__file__).resolve().parents[1]


@lru_cache(maxsize=4)
def code_version(where: Path = PACKAGE_DIR) -> str:
    """The code in ``where`` (ectskin's package folder): its git commit (12 hex digits) when
    it lies in a git checkout that tracks it, followed by "+" and a short hash of the
    uncommitted changes to the tracked files under it where there are any (a new file not yet
    added is not seen); otherwise "ectskin VERSION" (an installed package)."""
    try:
        _git(where, "ls-files", "--error-unmatch", "__init__.py")  # tracked here, not a copy
        head = _git(where, "rev-parse", "--short=12", "HEAD").strip()
        diff = _git(where, "diff", "HEAD", "--", ".")
    except (OSError, subprocess.SubprocessError):
        return f"ectskin {__version__}"
    if not diff:
        return head
    return f"{head}+{hashlib.blake2b(diff.encode(), digest_size=4).hexdigest()}"


def _flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(d, Mapping):
        return {prefix or "value": d}
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        out.update(_flatten(v, key) if isinstance(v, Mapping) else {key: v})
    return out


def settings_diff(old: Any, new: Any) -> str:
    """ "protocol.seed: 0 -> 1; epochs: None -> 5" for two nested settings dicts."""
    a, b = _flatten(plain(old)), _flatten(plain(new))
    parts = [
        f"{k}: {a.get(k)!r} -> {b.get(k)!r}"
        for k in sorted(set(a) | set(b))
        if a.get(k) != b.get(k)
    ]
    text = "; ".join(parts) or "unknown difference"
    return text if len(text) <= 400 else text[:397] + "..."


class StepState:
    """``OUT_DIR/reproduce.json``: per step its settings, done flag and seconds."""

    def __init__(self, out: Path) -> None:
        self.path = out / STATE_FILE
        self.steps: dict[str, dict[str, Any]] = {}
        if self.path.exists():
            d = read_json(self.path, "reproduce state")
            if not isinstance(d, dict) or d.get("format") != STATE_FORMAT:
                raise EctskinError(
                    f"{self.path}: not an ectskin reproduce state (format {STATE_FORMAT!r})"
                )
            self.steps = dict(d.get("steps") or {})

    def save(self) -> None:
        write_json_atomic(
            self.path,
            {"format": STATE_FORMAT, "version": 1, "ectskin": __version__, "steps": self.steps},
        )

    def settings(self, step: str) -> dict[str, Any] | None:
        """The settings ``step`` last started with (None: no record)."""
        return (self.steps.get(step) or {}).get("settings")

    def done(self, step: str, settings: Mapping[str, Any]) -> bool:
        s = self.steps.get(step) or {}
        return bool(s.get("done")) and s.get("settings") == plain(settings)

    def start(self, step: str, settings: Mapping[str, Any]) -> None:
        self.steps[step] = {"settings": plain(settings), "code": code_version(), "done": False}
        self.save()

    def finish(self, step: str, seconds: float, **info: Any) -> None:
        self.steps[step].update(done=True, seconds=float(seconds), **info)
        self.save()


@dataclass(frozen=True)
class Job:
    """One step for :meth:`StepRunner.steps`: as the arguments of :meth:`StepRunner.step`."""

    name: str
    settings: Mapping[str, Any]
    outputs: list[Path]
    fn: Callable[[], Any]


def _timed(fn: Callable[[], T]) -> tuple[T, float]:
    """``fn()`` and the seconds it took (module level: it runs in worker processes too)."""
    t0 = time.perf_counter()
    result = fn()
    return result, time.perf_counter() - t0


def _child_init(level: int) -> None:
    """A worker process of :meth:`StepRunner.steps`: log at the parent's level, as the command
    line does (the spawned process has no handlers of its own)."""
    logging.basicConfig(
        level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s", datefmt="%H:%M:%S"
    )


class StepRunner:
    """Runs the steps in order into ``out``, reusing finished ones and refusing conflicting
    leftovers (removed first with ``force``). ``timings`` {step: seconds} and ``reused`` [step]
    collect what happened."""

    def __init__(self, out: Path, force: bool) -> None:
        self.out = out
        self.force = force
        self.state = StepState(out)
        self.timings: dict[str, float] = {}
        self.reused: list[str] = []

    def _names(self, paths: list[Path]) -> str:
        return ", ".join(str(p.relative_to(self.out)) for p in paths)

    def _needs_run(self, name: str, settings: dict[str, Any], outputs: list[Path]) -> bool:
        """Whether step ``name`` must run: False when it finished with ``settings`` (recorded
        as reused); outputs of other settings are refused, or removed with ``force``."""
        existing = [p for p in outputs if p.exists()]
        if existing and self.state.done(name, settings):
            self.timings[name] = float(self.state.steps[name].get("seconds", 0.0))
            self.reused.append(name)
            log.info("%s: reusing the finished step (%s)", name, self._names(existing))
            made, now = self.state.steps[name].get("code"), code_version()
            if made != now:
                log.warning(
                    "%s: reused, but made by other code (%s; this is %s): its results are "
                    "that code's; remove %s (or use another output folder) to redo it", name,
                    made or "unrecorded", now, self._names(existing),
                )
            return False
        old = self.state.settings(name)
        resumable = old == settings  # interrupted with the same settings: resume in place
        if existing and not resumable:
            what = self._names(existing)
            if not self.force:
                why = (
                    f"they were made with other settings ({settings_diff(old, settings)})"
                    if old is not None
                    else f"their origin is unknown (no record in {STATE_FILE})"
                )
                raise EctskinError(
                    f"{self.out}: step {name!r} would overwrite {what}: {why}. Pass --overwrite "
                    f"to redo it, or use another output folder"
                )
            log.warning("%s: --overwrite: removing %s", name, what)
            for p in existing:
                shutil.rmtree(p) if p.is_dir() else p.unlink()
        elif existing:
            log.info("%s: resuming an interrupted step", name)
        return True

    def step(
        self, name: str, settings: Mapping[str, Any], outputs: list[Path], fn: Callable[[], T]
    ) -> T | None:
        """Run ``fn()`` for step ``name`` unless it finished with ``settings`` before.

        ``outputs``: the files/folders the step writes. Present but made with other settings (or
        of unknown origin) → error, or removed first with ``force``. Returns ``fn``'s result;
        a reused step returns None.
        """
        saved = plain(settings)  # as the state file holds them
        if not self._needs_run(name, saved, outputs):
            return None
        return self._run_here(name, saved, fn)

    def _run_here(self, name: str, settings: dict[str, Any], fn: Callable[[], T]) -> T:
        """Run a step that must run (:meth:`_needs_run` said so) in this process, recorded."""
        self.state.start(name, settings)
        result, dt = _timed(fn)
        self._finish(name, dt)
        return result

    def _finish(self, name: str, seconds: float) -> None:
        self.timings[name] = seconds
        self.state.finish(name, seconds)
        log.info("%s: done in %.1f s", name, seconds)

    def steps(self, jobs: list[Job], workers: int) -> dict[str, Any]:
        """:meth:`step` for each of ``jobs``, those that must run in up to ``workers`` processes
        at once (``concurrent.futures`` with spawned processes, so each job's ``fn`` must be
        picklable; its log records go to this process's handlers). Independent steps only:
        the jobs start in the order given and none sees another's outputs.

        Returns {name: fn's result} of the jobs run now. With ``workers`` 1, or one job to run,
        they run here in order. A failed job is recorded as not done, the others finish, and the
        first failure is raised.
        """
        todo = []
        for job in jobs:
            settings = plain(job.settings)
            if self._needs_run(job.name, settings, job.outputs):
                todo.append((job, settings))
        if workers <= 1 or len(todo) <= 1:
            return {job.name: self._run_here(job.name, s, job.fn) for job, s in todo}
        results: dict[str, Any] = {}
        errors: list[BaseException] = []
        ctx = multiprocessing.get_context("spawn")
        level = logging.getLogger().getEffectiveLevel()
        n = min(workers, len(todo))
        with ProcessPoolExecutor(
            n, mp_context=ctx, initializer=_child_init, initargs=(level,)
        ) as pool:
            futures = {}
            for job, settings in todo:
                self.state.start(job.name, settings)
                futures[pool.submit(_timed, job.fn)] = job.name
            log.info("running %s in %d processes", ", ".join(futures.values()), n)
            for fut in as_completed(futures):
                name = futures[fut]
                try:
                    results[name], dt = fut.result()
                except BaseException as exc:  # recorded, raised after the others finish
                    log.error("%s failed: %s", name, exc)
                    errors.append(exc)
                    continue
                self._finish(name, dt)
        if errors:
            raise errors[0]
        return results

    def adopt(self, name: str, settings: Mapping[str, Any]) -> None:
        """Record step ``name`` as finished with ``settings`` without running it (its outputs,
        found in the folder, were checked by the caller to match); the next :meth:`step`
        reuses them."""
        self.state.start(name, settings)
        self.state.finish(name, 0.0, adopted=True)
