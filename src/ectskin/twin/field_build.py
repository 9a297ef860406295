"""Building response fields on Dask distributed, cached on disk chunk by chunk, and loading them.

A field (:class:`~ectskin.twin.field.ResponseField`) is cut into chunks: the untouched readout,
and per face and grid column u one chunk of contact nodes (every v × every force) and one of
hover nodes (every v × every height), solved by :mod:`ectskin.twin.field_solve`. The chunks run
on Dask distributed: a new ``LocalCluster`` (worker processes with one thread each) by default,
or the scheduler at ``scheduler="tcp://HOST:PORT"`` (its workers need ectskin installed; the
results come back to this process, which alone writes the cache); ``workers=0`` solves them
here, one after another.

The cache: ``cache_dir / <spec key> /`` (:meth:`FieldSpec.key`) holds ``manifest.json`` (the
spec, the key, the chunk names, whether the field is complete), ``chunks/<name>.npy`` (each
written atomically the moment it is solved, :func:`ectskin._files.atomic_write`) and, once every
chunk is there, ``field.npz`` (:meth:`ResponseField.save`). A build that is killed keeps its
finished chunks and the next build solves only the missing ones; a complete field loads from
``field.npz`` without starting anything.

Each chunk is solved with BLAS limited to one thread (``threadpoolctl``) and depends only on
the spec and the chunk, so a field is bit-identical for any number of workers. The contact
rows' solves may run batched on a torch device (``device``, or ``$ECTSKIN_SOLVE_DEVICE``:
"cuda" for a GPU, :mod:`ectskin.electrostatics.batched`): the same readouts to round-off
(about 1e-14 relative), so the device is not part of the cache key; a field is bit-identical
for any number of workers on one device.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

import ectskin
from ectskin._check import EctskinError
from ectskin._dask import dask_client
from ectskin._files import atomic_write, read_json_object, write_json_atomic
from ectskin.electrostatics.batched import solve_device
from ectskin.twin.field import ResponseField
from ectskin.twin.field_solve import Chunk, chunks_of, solve_chunk
from ectskin.twin.field_spec import FIELD_FORMAT, FieldSpec, physics_digest

log = logging.getLogger(__name__)

#: seconds to wait for a scheduler given by address
CONNECT_TIMEOUT_S = 10.0
MANIFEST = "manifest.json"
FIELD_FILE = "field.npz"


@dataclass(frozen=True)
class BuildReport:
    """What :func:`build_chunks` did: chunks in all, already cached, solved now, and whether
    every field is complete."""

    total: int
    cached: int
    solved: int
    complete: bool
    seconds: float


def field_dir(spec: FieldSpec, cache_dir: str | os.PathLike) -> Path:
    """The cache folder of ``spec``'s field: ``cache_dir / spec.key()``."""
    return Path(os.fspath(cache_dir)) / spec.key()


def _chunk_shape(spec: FieldSpec, chunk: Chunk) -> tuple[int, ...]:
    if chunk.kind == "untouched":
        return (spec.n_pairs,)
    n_v = spec.grid(chunk.face)[1].size
    n = spec.force_nodes if chunk.kind == "contact" else spec.height_nodes
    return (n_v, n, spec.n_pairs)


# ---------------------------------------------------------------------- the cache
def _chunk_path(folder: Path, chunk: Chunk) -> Path:
    return folder / "chunks" / f"{chunk.name}.npy"


def _write_chunk(folder: Path, chunk: Chunk, values: np.ndarray) -> None:
    def write(fh) -> None:
        buf = io.BytesIO()
        np.save(buf, np.asarray(values, dtype=np.float64), allow_pickle=False)
        fh.write(buf.getvalue())

    atomic_write(_chunk_path(folder, chunk), write, what=f"field chunk {chunk.name}")


def _read_chunk(folder: Path, spec: FieldSpec, chunk: Chunk) -> np.ndarray | None:
    """A cached chunk, or None if it is missing or unreadable (then it is solved again)."""
    path = _chunk_path(folder, chunk)
    try:
        arr = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        log.warning("%s: unreadable (%s); solving it again", path, exc)
        return None
    if arr.shape != _chunk_shape(spec, chunk) or not np.all(np.isfinite(arr)):
        log.warning("%s: shape %s or values do not fit the spec; solving it again", path, arr.shape)
        return None
    return arr


def _manifest(spec: FieldSpec, complete: bool) -> dict[str, Any]:
    return {
        "format": FIELD_FORMAT,
        "key": spec.key(),
        "ectskin": ectskin.__version__,
        "complete": complete,
        "chunks": [c.name for c in chunks_of(spec)],
        "spec": spec.to_dict(),
    }


def _is_complete(folder: Path, spec: FieldSpec) -> bool:
    path = folder / MANIFEST
    if not path.is_file() or not (folder / FIELD_FILE).is_file():
        return False
    man = read_json_object(path, "field manifest")
    return bool(man.get("complete")) and man.get("key") == spec.key()


def _assemble(folder: Path, spec: FieldSpec) -> ResponseField:
    """The field from its cached chunks; written to ``field.npz`` and marked complete."""
    read = {c.name: _read_chunk(folder, spec, c) for c in chunks_of(spec)}
    missing = [n for n, a in read.items() if a is None]
    parts = {n: a for n, a in read.items() if a is not None}
    if missing:
        raise EctskinError(
            f"{folder}: field incomplete, {len(missing)} chunk(s) missing (e.g. {missing[0]}); "
            "build it again to resume"
        )
    contact: dict[str, np.ndarray] = {}
    hover: dict[str, np.ndarray] = {}
    for face in spec.face_names:
        n_u = spec.grid(face)[0].size
        contact[face] = np.stack([parts[Chunk("contact", face, i).name] for i in range(n_u)])
        if spec.height_nodes:
            hover[face] = np.stack([parts[Chunk("hover", face, i).name] for i in range(n_u)])
    field = ResponseField(spec, parts["untouched"], contact, hover)
    field.save(folder / FIELD_FILE)
    write_json_atomic(folder / MANIFEST, _manifest(spec, complete=True))
    return field


# ---------------------------------------------------------------------- where chunks run
@contextlib.contextmanager
def _client(scheduler: str | None, workers: int | None, n_tasks: int) -> Iterator[Any]:
    """A Dask client (a new LocalCluster, or the scheduler at ``scheduler``), or None for
    ``workers=0`` (solve here). Closes what it opened."""
    if scheduler is None and workers == 0:
        yield None
        return
    if scheduler is None:
        n = workers if workers is not None else len(os.sched_getaffinity(0))
        n = max(1, min(n, n_tasks))
    else:
        n = 0  # the scheduler's workers
    with dask_client(
        n,
        scheduler,
        option="scheduler",
        wait_for_workers=True,
        timeout_s=CONNECT_TIMEOUT_S,
        what="response field",
    ) as client:
        yield client


def _check_workers(workers: int | None) -> None:
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 0
    ):
        raise EctskinError(f"workers must be None (one per core) or an integer >= 0, got {workers!r}")


# ---------------------------------------------------------------------- the public API
def build_chunks(
    specs: Sequence[FieldSpec],
    cache_dir: str | os.PathLike,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    max_chunks: int | None = None,
    device: str | None = None,
) -> BuildReport:
    """Solve the chunks of ``specs``' fields that are not cached yet (all specs on one cluster).

    ``max_chunks`` stops after that many newly solved chunks (a time budget; the next build
    resumes). Complete fields are assembled into ``field.npz``. ``device``: where the contact
    rows' solves run (:func:`~ectskin.electrostatics.batched.solve_device`: a torch device,
    "auto", or None for ``$ECTSKIN_SOLVE_DEVICE``, unset meaning NumPy).
    """
    specs = list(specs)
    for k, s in enumerate(specs):
        if not isinstance(s, FieldSpec):
            raise EctskinError(f"specs[{k}] must be a FieldSpec, got {type(s).__name__}")
    _check_workers(workers)
    if max_chunks is not None and (isinstance(max_chunks, bool) or not isinstance(max_chunks, int)
                                   or max_chunks < 0):
        raise EctskinError(f"max_chunks must be None or an integer >= 0, got {max_chunks!r}")
    device = solve_device(device)
    t0 = time.perf_counter()
    todo: list[tuple[FieldSpec, Path, Chunk]] = []
    total = cached = 0
    for spec in specs:
        folder = field_dir(spec, cache_dir)
        chunks = chunks_of(spec)
        total += len(chunks)
        if _is_complete(folder, spec):
            cached += len(chunks)
            continue
        if not (folder / MANIFEST).is_file():
            write_json_atomic(folder / MANIFEST, _manifest(spec, complete=False))
        for c in chunks:
            if _chunk_path(folder, c).is_file() and _read_chunk(folder, spec, c) is not None:
                cached += 1
            else:
                todo.append((spec, folder, c))
    if max_chunks is not None:
        todo = todo[:max_chunks]
    log.info("response field: %d chunk(s), %d cached, %d to solve (solves on %s)", total, cached,
             len(todo), device or "numpy")
    solved = 0
    if todo:
        with _client(scheduler, workers, len(todo)) as client, tqdm(
            total=len(todo), desc="field chunks", unit="chunk", disable=not progress
        ) as bar:
            for (_, folder, chunk), values in _run(client, todo, device):
                _write_chunk(folder, chunk, values)
                solved += 1
                bar.update(1)
    complete = True
    for spec in specs:
        folder = field_dir(spec, cache_dir)
        if _is_complete(folder, spec):
            continue
        if all(_chunk_path(folder, c).is_file() for c in chunks_of(spec)):
            _assemble(folder, spec)
        else:
            complete = False
    return BuildReport(total, cached, solved, complete, time.perf_counter() - t0)


def _run(
    client, todo: list[tuple[FieldSpec, Path, Chunk]], device: str | None = None
) -> Iterator[tuple[tuple, np.ndarray]]:
    """Yield (job, values) as chunks finish; a chunk's error is raised here (naming it) and the
    chunks still running are cancelled."""
    if client is None:
        for job in todo:
            yield job, _solve_named(job[0], job[2], device)
        return
    from distributed import as_completed  # deferred: start-up speed of the package

    physics = physics_digest()
    extra = () if device is None else (device,)
    futures = [
        client.submit(solve_chunk, job[0], job[2], physics, *extra, pure=False) for job in todo
    ]
    jobs = {f.key: job for f, job in zip(futures, todo)}
    try:
        for fut in as_completed(futures):
            job = jobs[fut.key]
            try:
                values = fut.result()
            except EctskinError as exc:
                raise EctskinError(f"field chunk {job[2].name}: {exc}") from None
            yield job, values
    finally:
        for fut in futures:
            fut.cancel()


def _solve_named(spec: FieldSpec, chunk: Chunk, device: str | None = None) -> np.ndarray:
    try:
        return solve_chunk(spec, chunk) if device is None else solve_chunk(spec, chunk, device=device)
    except EctskinError as exc:
        raise EctskinError(f"field chunk {chunk.name}: {exc}") from None


def build_fields(
    specs: Sequence[FieldSpec],
    cache_dir: str | os.PathLike,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    device: str | None = None,
) -> list[ResponseField]:
    """The fields of ``specs`` (several states on one cluster), built where not cached
    (``device``: :func:`build_chunks`)."""
    report = build_chunks(
        specs, cache_dir, scheduler=scheduler, workers=workers, progress=progress, device=device
    )
    if not report.complete:  # (cannot happen without max_chunks)
        raise EctskinError("response fields incomplete after the build; build them again")
    return [load_field(s, cache_dir) for s in specs]


def build_field(
    spec: FieldSpec,
    cache_dir: str | os.PathLike,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    device: str | None = None,
) -> ResponseField:
    """The field of ``spec``: loaded from ``cache_dir`` if complete, else built (resuming from
    the cached chunks) on Dask: a LocalCluster of ``workers`` processes (default one per core),
    the scheduler at ``scheduler`` (tcp://HOST:PORT), or here (``workers=0``)."""
    return build_fields(
        [spec], cache_dir, scheduler=scheduler, workers=workers, progress=progress, device=device
    )[0]


def load_field(source: FieldSpec | str | os.PathLike, cache_dir: str | os.PathLike | None = None) -> ResponseField:
    """A complete field: by its spec from ``cache_dir``, or from a field folder or ``field.npz``."""
    if isinstance(source, FieldSpec):
        if cache_dir is None:
            raise EctskinError("load_field(spec, cache_dir): cache_dir is needed with a spec")
        folder = field_dir(source, cache_dir)
        if not _is_complete(folder, source):
            raise EctskinError(
                f"{folder}: no complete response field for this spec (key {source.key()[:12]}…); "
                "build it first (build_field)"
            )
        field = ResponseField.from_file(folder / FIELD_FILE)
        if field.key != source.key():
            raise EctskinError(f"{folder / FIELD_FILE}: holds key {field.key}, expected {source.key()}")
        return field
    path = Path(os.fspath(source))
    if path.is_dir():
        path = path / FIELD_FILE
    return ResponseField.from_file(path)
