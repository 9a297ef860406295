"""The node solves of a response field (:mod:`ectskin.twin.field`), one grid row at a time.

* **Contact** (the finger pressing with force F): the twin's direct solve,
  :meth:`SensorModel.capacitance`. The finger dents the skin under it and bends the body, so
  the electrode panels move with the point and the force and nothing of the electrode block can
  be factored once: each node is a full method-of-moments solve. With a solve device (a torch
  device, :func:`~ectskin.electrostatics.batched.solve_device`) a row's nodes are solved as one
  batch there (batched Cholesky on a GPU), and so are the hover rows' Schur complements
  (:func:`~ectskin.electrostatics.batched_schur.schur_batch`). (Keeping the electrodes where
  the untouched state has them and moving only the finger would allow the Schur path below for
  contact too; it is off by up to a quarter of the finger's signal near the tip at 2 N, see
  ``docs/field.md``.)
* **Hover** (force 0, height h): a finger that does not press leaves the body as it is, so the
  electrode panels (and the chamber cavities) are the untouched state's. They are factored once
  per state and process (:class:`~ectskin.electrostatics.schur.FixedConductors`,
  :func:`untouched_conductors`) and every finger position and height adds only its own panels
  (with the fingertip's own potential block, computed once per shape): the same readout as the
  direct solve, to round-off. That the finger at force 0 moves no electrode panel is checked on
  every row. For the same reason the
  row's fingertips rest on one untouched skin and are placed together
  (:func:`~ectskin.twin.finger.hovering`), then turned into panels by the twin's own calls.
* **Untouched**: the state without a finger.

Every function here is deterministic: its result depends only on its arguments (what is kept
between rows, the state's factor and the fingertip's shapes and blocks, is a pure function of
the sensor, the state and the shape), so a field is the same whichever worker solves which row.
"""

from __future__ import annotations

import contextlib
import logging
import weakref
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from ectskin._check import EctskinError
from ectskin._malloc import keep_freed_memory
from ectskin.electrostatics import EPS0_PF_PER_MM, Panels
from ectskin.electrostatics.batched import readout_batch
from ectskin.electrostatics.batched_schur import schur_batch
from ectskin.electrostatics.schur import FixedConductors
from ectskin.twin.field_spec import FieldSpec, physics_digest
from ectskin.twin.finger import hovering
from ectskin.twin.mechanics import Touch
from ectskin.twin.sensor import SensorModel

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Chunk:
    """One unit of work: ``kind`` "untouched", or "contact" / "hover" nodes of grid column
    ``iu`` on ``face``."""

    kind: str
    face: str = ""
    iu: int = -1

    @property
    def name(self) -> str:
        return "untouched" if self.kind == "untouched" else f"{self.kind}-{self.face}-u{self.iu:03d}"


def chunks_of(spec: FieldSpec) -> list[Chunk]:
    """The chunks of ``spec``'s field, in a fixed order."""
    out = [Chunk("untouched")]
    for face in spec.face_names:
        n_u = spec.grid(face)[0].size
        kinds = ("contact", "hover") if spec.height_nodes else ("contact",)
        out += [Chunk(kind, face, iu) for iu in range(n_u) for kind in kinds]
    return out


_SENSORS: dict[str, SensorModel] = {}  # per worker process: the sensor of a spec, by key

#: whether this process has set ectskin._malloc's thresholds (once per process)
_MALLOC_SET: list[bool] = []


def _keep_freed_memory_once() -> bool:
    """:func:`ectskin._malloc.keep_freed_memory` in this process, once: a process that solves
    nodes without having been started by the CLI or a local cluster (which set it already), e.g.
    an in-process build (``workers=0``), keeps the freed arrays of one node for the next instead
    of faulting them in again (the same numbers either way)."""
    if not _MALLOC_SET:
        _MALLOC_SET.append(keep_freed_memory())
    return _MALLOC_SET[0]


def solve_chunk(
    spec: FieldSpec, chunk: Chunk, physics: str | None = None, device: str | None = None
) -> np.ndarray:
    """The node values of one chunk (BLAS on one thread, so the result is the same anywhere).

    ``physics``: the :func:`~ectskin.twin.field_spec.physics_digest` of the process that keys the
    cache; a worker whose ectskin computes other physics refuses the chunk. ``device``: a torch
    device for the contact rows' batched solves (:func:`contact_row`), None for NumPy.
    """
    if physics is not None and physics != physics_digest():
        raise EctskinError(
            "this Dask worker's ectskin differs from the building process's (physics digest "
            f"{physics_digest()[:12]} here, {physics[:12]} there); install the same ectskin on "
            "the workers"
        )
    _keep_freed_memory_once()
    key = spec.key()
    sensor = _SENSORS.get(key)
    if sensor is None:
        if len(_SENSORS) >= 4:
            _SENSORS.pop(next(iter(_SENSORS)))
        sensor = _SENSORS[key] = spec.sensor()
    with threadpool_limits(limits=1), _torch_threads(1 if device else None):
        if chunk.kind == "untouched":
            return untouched_readout(sensor, spec.inflation_ml)
        u = float(spec.grid(chunk.face)[0][chunk.iu])
        v = spec.grid(chunk.face)[1]
        if chunk.kind == "contact":
            return contact_row(
                sensor, spec.inflation_ml, chunk.face, u, v, spec.forces(), device=device
            )
        return hover_row(sensor, spec.inflation_ml, chunk.face, u, v, spec.heights(), device)


# ---------------------------------------------------------------------- the rows
def untouched_readout(sensor: SensorModel, inflation_ml) -> np.ndarray:
    """(n_pairs,) pF: the state's readout without a finger."""
    return sensor.capacitance(inflation_ml)[0]


def contact_row(
    sensor: SensorModel, inflation_ml, face: str, u_mm: float, v_mm: np.ndarray, forces_n,
    device: str | None = None,
) -> np.ndarray:
    """(n_v, n_forces, n_pairs) pF: the finger pressing at (u, v_k) with each force (direct).

    ``device`` None: :meth:`SensorModel.capacitance` point by point. A torch device ("cpu",
    "cuda"): the row's n_v × n_forces method-of-moments solves as one batch
    (:func:`~ectskin.electrostatics.batched.readout_batch`; the panels are placed as the twin
    places them, :meth:`SensorModel.solve_sets`), the same readouts to round-off; a node that
    does not factor is solved with a refined fingertip, as the direct solve does.
    """
    forces = np.asarray(forces_n, dtype=np.float64)
    touches = [Touch(face, (float(u_mm), float(v))) for v in v_mm]
    if device is None:
        return np.stack([sensor.capacitance(inflation_ml, t, forces) for t in touches])
    sets = [row for t in touches for row in sensor.solve_sets(inflation_ml, t, forces)]
    cavities = sensor.chamber_eps_r is not None and sensor.chamber_eps_r != sensor.eps_r
    out, ok = readout_batch(
        [p for p, _, _ in sets], eps_r=sensor.eps_r, n_electrodes=sensor.n_electrodes,
        pairs=sensor.layout.pairs, device=device, chamber_eps_r=sensor.chamber_eps_r,
        blocks=[b for _, b, _ in sets],
        cells=[c for _, _, c in sets] if cavities else None,  # type: ignore[misc]
    )
    n_f = forces.size
    for k in np.flatnonzero(~ok):
        out[k] = sensor.refined_readout(
            inflation_ml, touches[k // n_f], forces, None, None, int(k % n_f), *sets[k]
        )
    return out.reshape(len(touches), n_f, -1)


def hover_row(
    sensor: SensorModel, inflation_ml, face: str, u_mm: float, v_mm: np.ndarray, heights_mm,
    device: str | None = None,
) -> np.ndarray:
    """(n_v, n_heights, n_pairs) pF: the finger hovering over (u, v_k) at each height, force 0,
    by the Schur path over the untouched electrodes (module docstring); with a torch
    ``device`` the row's sets as one batch there
    (:func:`~ectskin.electrostatics.batched_schur.schur_batch`)."""
    heights = np.asarray(heights_mm, dtype=np.float64)
    zeros = np.zeros(heights.size)
    solver = untouched_conductors(sensor, inflation_ml)
    _check_unmoved(sensor, inflation_ml, Touch(face, (float(u_mm), float(v_mm[0]))), solver.panels)
    cavities = sensor.chamber_eps_r is not None and sensor.chamber_eps_r != sensor.eps_r
    touches = [Touch(face, (float(u_mm), float(v))) for v in v_mm]
    # the fingertips of the whole row placed at once (the finger at force 0 leaves the body as
    # it is); the panels and any direct solve below are the twin's own calls
    with hovering(sensor.manipulator, sensor.finger, inflation_ml, touches, heights):
        fingers = [
            [(p, blocks[0][1]) for p, blocks in
             sensor.finger_sets(inflation_ml, t, zeros, heights_mm=heights)]
            for t in touches
        ]  # n_v lists of n_heights (panels, their own block)
        try:  # the whole row in one batch
            flat = _readouts(
                sensor, solver, [p for per_v in fingers for p in per_v], cavities, device
            )
            return flat.reshape(len(v_mm), heights.size, -1)
        except EctskinError:
            pass
        return _one_by_one(
            sensor, inflation_ml, solver, touches, fingers, heights, cavities, device
        )


#: per sensor, the last few states' untouched electrodes factored (:func:`untouched_conductors`)
_UNTOUCHED: weakref.WeakKeyDictionary[SensorModel, dict[bytes, FixedConductors]] = (
    weakref.WeakKeyDictionary()
)
_UNTOUCHED_KEPT = 4


def untouched_conductors(sensor: SensorModel, inflation_ml) -> FixedConductors:
    """The untouched state's electrode panels (and cavity cells) factored for the Schur path,
    once per sensor and state: every hover row of a state adds its fingers to the same factor.
    A pure function of the sensor and the state (the fingers' own blocks are passed in, so the
    factor carries nothing from one row to the next), so the rows' values do not depend on
    which rows a process solved before."""
    p = sensor.manipulator.check_inflation(inflation_ml)
    per_sensor = _UNTOUCHED.setdefault(sensor, {})
    solver = per_sensor.get(p.tobytes())
    if solver is None:
        base = sensor.electrode_panels(p, None, [0.0])[0]
        cells = None
        if sensor.chamber_eps_r is not None and sensor.chamber_eps_r != sensor.eps_r:
            pts, vols = sensor.cavity_cells(p, None, [0.0])
            cells = (pts[0], vols[0])
        solver = FixedConductors(base, sensor.eps_r, cells=cells)
        if len(per_sensor) >= _UNTOUCHED_KEPT:
            per_sensor.pop(next(iter(per_sensor)))
        per_sensor[p.tobytes()] = solver
    return solver


def _one_by_one(
    sensor, inflation_ml, solver, touches, fingers, heights, cavities, device=None
) -> np.ndarray:
    """The hover row point by point, where the batch failed: a point whose Schur complement is
    not positive definite is solved directly."""
    zeros = np.zeros(heights.size)
    out = np.empty((len(touches), heights.size, sensor.layout.n_pairs))
    for k, (touch, per_v) in enumerate(zip(touches, fingers)):
        try:
            out[k] = _readouts(sensor, solver, per_v, cavities, device)
        except EctskinError as exc:
            # a fingertip panel too close to a wire panel: the twin's own solve refines it
            log.debug("hover at %s: %s; solving directly", touch, exc)
            out[k] = sensor.capacitance(inflation_ml, touch, zeros, heights_mm=heights)
    return out


def _readouts(
    sensor: SensorModel, solver: FixedConductors, fingers: list[tuple[Panels, np.ndarray]],
    cavities: bool, device: str | None = None,
) -> np.ndarray:
    """(len(fingers), n_pairs) C_ij = −K_ij of the fingers (panels, their own potential block),
    with the cavities' first-order term as the twin adds it (:class:`SensorModel`,
    ``chamber_eps_r``); batched on ``device`` where given and the fingers have one panel count.
    Raises :class:`EctskinError` where a Schur complement does not factor, either way."""
    n = sensor.n_electrodes
    n_s = n if cavities else None
    panels, blocks = [p for p, _ in fingers], [b for _, b in fingers]
    if device is not None and len({p.n_panels for p in panels}) == 1:
        K, S, ok = schur_batch(solver, panels, blocks, device=device, sensitivity_columns=n_s)
        if not ok.all():
            raise EctskinError("the Schur complement of an added finger is not positive definite")
    else:
        K, S = solver.capacitance(panels, sensitivity_columns=n_s, blocks=blocks)
    Kn = K[:, :n, :n]
    if S is not None:
        assert sensor.chamber_eps_r is not None  # (cavities says so)
        Kn = Kn + EPS0_PF_PER_MM * (sensor.chamber_eps_r - sensor.eps_r) * S
    pairs = sensor.layout.pairs
    return -Kn[:, pairs[:, 0], pairs[:, 1]]


@contextlib.contextmanager
def _torch_threads(n: int | None) -> Iterator[None]:
    """Torch's CPU threads limited to ``n`` (None: untouched) for the duration."""
    if n is None:
        yield
        return
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _check_unmoved(sensor: SensorModel, inflation_ml, touch: Touch, base: Panels) -> None:
    """Refuse the hover path if a finger at force 0 moves the electrode panels."""
    moved = sensor.electrode_panels(inflation_ml, touch, [0.0])[0]
    shift = np.inf
    if moved.n_panels == base.n_panels:
        shift = float(np.max(np.abs(moved.centres - base.centres), initial=0.0))
    if shift > 0.0:
        raise EctskinError(
            f"response field: a finger hovering at {touch} (force 0) moves the electrode panels "
            f"(by up to {shift:.3g} mm); the hover nodes assume it leaves the body as it is"
        )
