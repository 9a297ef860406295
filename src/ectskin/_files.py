"""Atomic file writes and JSON conversion: one policy for every result file ectskin writes.

Every result, checkpoint, report and figure is written through :func:`atomic_write`: the bytes go
to a hidden temporary file ``.<name>.tmp-<pid>`` in the target's folder, are flushed to disk
(``fsync``) and renamed onto the target with ``os.replace``. A reader sees the old file or the new
one, never half of one; on any error (a full disk included) the temporary file is removed, the
target is untouched and the error is one :class:`~ectskin.EctskinError` naming the file.
A run that was killed leaves its temporary file behind; the next write into the same folder removes
such stale files of the same target (:func:`remove_stale_temps`: only those whose process is gone).

JSON policy (:func:`to_jsonable`): NumPy scalars and arrays become numbers and lists, tuples
become lists, paths become strings, dataclasses and objects with ``to_dict()`` become dicts, dict
keys become strings as JSON spells them (``True`` → ``"true"``, ``None`` → ``"null"``), and a
non-finite float (NaN, ±inf) becomes ``null``: strict JSON has no NaN, and every JSON file
ectskin writes can be read by any JSON parser. Readers treat ``null`` as "not available". So
``to_jsonable(obj)`` is what a file written from ``obj`` reads back as: compare settings with a
stored file through it.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from ectskin._check import EctskinError

TMP_MARK = ".tmp-"

log = logging.getLogger(__name__)


def temp_path(path: Path) -> Path:
    """The hidden temporary sibling ``.<name>.tmp-<pid>`` that an atomic write of ``path`` uses."""
    return path.with_name(f".{path.name}{TMP_MARK}{os.getpid()}")


def _pid_alive(pid: int) -> bool:
    """True unless no process ``pid`` exists (a process of another user counts as alive)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale_temps(path: str | os.PathLike) -> list[Path]:
    """Remove the temporary files ``.<name>.tmp-<pid>`` of ``path`` left by killed runs.

    Only files whose process no longer exists are removed (a run that is still writing keeps its
    file); this process's own is kept too. Returns the removed paths; never raises.
    """
    path = Path(os.fspath(path))
    prefix = f".{path.name}{TMP_MARK}"
    removed: list[Path] = []
    try:
        candidates = [p for p in path.parent.iterdir() if p.name.startswith(prefix)]
    except OSError:
        return removed
    for p in candidates:
        pid_text = p.name[len(prefix) :]
        if not pid_text.isdigit() or int(pid_text) == os.getpid() or _pid_alive(int(pid_text)):
            continue
        try:
            p.unlink()
        except OSError:
            continue
        removed.append(p)
        log.info("removed %s, left by an earlier run (process %s) that did not finish", p, pid_text)
    return removed


def os_error_text(exc: OSError) -> str:
    """The short reason of an ``OSError``: "No space left on device", "Permission denied"."""
    if exc.errno:
        return os.strerror(exc.errno)
    return exc.strerror or str(exc)


def atomic_write(
    path: str | os.PathLike, write: Callable[[IO[bytes]], Any], *, what: str = "the file"
) -> Path:
    """Call ``write(fh)`` on a binary temporary file, fsync it and rename it onto ``path``.

    The parent folder is created; stale temporary files of ``path`` are removed first
    (:func:`remove_stale_temps`). On any exception the temporary file is removed, ``path`` is left
    as it was, and an ``OSError`` (disk full, permissions) becomes one :class:`EctskinError` that
    names the file and says that nothing was written (``what`` names the content in it).
    """
    path = Path(os.fspath(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EctskinError(f"{path}: cannot create its folder ({os_error_text(exc)})") from None
    remove_stale_temps(path)
    tmp = temp_path(path)
    try:
        with open(tmp, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        hint = "; free some space and run it again" if exc.errno == errno.ENOSPC else ""
        raise EctskinError(
            f"{path}: cannot write {what} ({os_error_text(exc)}); nothing was written there{hint}"
        ) from None
    finally:
        tmp.unlink(missing_ok=True)
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    data = text.encode("utf-8")
    return atomic_write(path, lambda fh: fh.write(data))


def to_jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON values under the module's policy (non-finite floats → ``None``)."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(asdict(obj))
    if isinstance(obj, Mapping):
        return {_json_key(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if hasattr(obj, "to_dict") and callable(obj.to_dict):
        return to_jsonable(obj.to_dict())
    if hasattr(obj, "ndim") and getattr(obj, "ndim", None) == 0 and hasattr(obj, "item"):
        return to_jsonable(obj.item())  # a 0-d tensor
    return obj


def _json_key(key: Any) -> str:
    """A dict key as JSON writes it: ``True`` → "true", ``None`` → "null", others ``str``."""
    if key is None:
        return "null"
    if isinstance(key, bool | np.bool_):
        return "true" if key else "false"
    return str(key)


def json_text(obj: Any, *, indent: int | None = 1, compact: bool = False) -> str:
    """Strict JSON text of ``obj`` under the module's policy (``compact`` for network messages)."""
    if compact:
        return json.dumps(to_jsonable(obj), allow_nan=False, separators=(",", ":"))
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False) + "\n"


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Write ``obj`` as indented strict JSON to ``path`` atomically."""
    return write_text_atomic(path, json_text(obj))


def read_json(path: str | os.PathLike, what: str = "file") -> Any:
    """Read a JSON file, turning a missing or malformed file into one clear EctskinError."""
    path = Path(os.fspath(path))
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise EctskinError(f"{path}: {what} not found") from None
    except UnicodeDecodeError:
        raise EctskinError(f"{path}: {what} is not UTF-8 text") from None
    except OSError as exc:
        raise EctskinError(f"{path}: cannot read {what}: {exc.strerror}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise EctskinError(
            f"{path}: {what} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None


def read_json_object(path: str | os.PathLike, what: str = "file") -> dict[str, Any]:
    """:func:`read_json` of a file that must hold a JSON object (a dict)."""
    obj = read_json(path, what)
    if not isinstance(obj, dict):
        raise EctskinError(
            f"{path}: {what} must hold a JSON object, found a JSON {type(obj).__name__}"
        )
    return obj


def save_figure_atomic(fig: Any, path: str | os.PathLike, *, dpi: int = 110) -> Path:
    """``fig.savefig`` to ``path`` atomically; the format follows ``path``'s suffix."""
    path = Path(os.fspath(path))
    fmt = path.suffix.lstrip(".") or "png"
    return atomic_write(path, lambda fh: fig.savefig(fh, dpi=dpi, format=fmt))
