"""The finger nuisances' columns from response fields: ∂C/∂ln E and ∂C/∂ln R of each state.

The inversion fits each pressing finger's pulp modulus x = ln(E / E0) and radius r = ln(R / R0)
where it has their columns (:mod:`ectskin.inversion.finger_nuisance`):
:func:`~ectskin.twin.bound_modulus.modulus_table` and
:func:`~ectskin.inversion.finger_nuisance.radius_table` take them by direct solves, node by
node (minutes per state on one core). :func:`finger_tables` takes them from response fields of
the same state with a softer and a stiffer pulp (E0 e^(±h)) and a smaller and a bigger
fingertip (R0 e^(±h)): central differences of two fields' contact nodes, built as any field is
(:func:`~ectskin.twin.field_build.build_fields`: Dask, batched solves, a GPU where one is
given, cached by their specs and resumable) on a coarser grid than the state's own
(:data:`FINGER_FIELD_SPACING_MM`, :data:`FINGER_FIELD_FORCE_NODES`, no hover part: the
nuisances are a pressing finger's). Each is a :class:`~ectskin.twin.bound_modulus.ModulusTable`
of the state (nodes: the coarse field's grid; forces: its Chebyshev nodes), which the inversion
interpolates cubically in (u, v, ln F).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import replace

from ectskin._check import EctskinError
from ectskin.twin.bound_modulus import MODULUS_STEP, ModulusTable
from ectskin.twin.field_build import build_fields
from ectskin.twin.field_spec import FieldSpec

__all__ = ["FINGER_FIELD_FORCE_NODES", "FINGER_FIELD_SPACING_MM", "FINGER_STEPS",
           "RADIUS_STEP", "finger_field_specs", "finger_tables"]

#: the central difference's step in ln R (a 5 % smaller and bigger fingertip)
RADIUS_STEP = 0.05
#: each nuisance's step of the central difference, ln units
FINGER_STEPS = {"modulus": MODULUS_STEP, "radius": RADIUS_STEP}
#: the coarse fields' grid step (du, dv) mm: the columns vary over the pad's size (a contact
#: disc of 3-6 mm radius), and 8 mm nodes cost a twentieth of the quick grid's solves each
FINGER_FIELD_SPACING_MM = (8.0, 8.0)
#: their force nodes (the cubic in ln F needs 4)
FINGER_FIELD_FORCE_NODES = 4


def finger_field_specs(spec: FieldSpec, name: str, *,
                       spacing_mm: tuple[float, float] = FINGER_FIELD_SPACING_MM,
                       force_nodes: int = FINGER_FIELD_FORCE_NODES) -> tuple[FieldSpec, FieldSpec]:
    """The specs (smaller, bigger) of ``spec``'s state whose finger's nuisance ``name``
    ("modulus" or "radius") is e^(∓step) times ``spec``'s, on the coarse grid (no graded bands,
    no hover part): steps of ``spacing_mm``, never finer than ``spec``'s own (a state's field
    on a coarser grid keeps its steps), and ``force_nodes`` forces."""
    if name not in FINGER_STEPS:
        raise EctskinError(f"Invalid value for 'finger nuisance': allowed values are "
                           f"{list(FINGER_STEPS)}; got {name!r}")
    f, h = spec.finger, FINGER_STEPS[name]
    field = "pulp_modulus_mpa" if name == "modulus" else "radius_mm"
    steps = (max(float(spacing_mm[0]), float(spec.spacing_mm[0])),
             max(float(spacing_mm[1]), float(spec.spacing_mm[1])))
    coarse = replace(spec, spacing_mm=steps, force_nodes=force_nodes, height_nodes=0,
                     fine_spacing_mm=None, refine_u_mm=(), refine_v_mm=())
    return tuple(replace(coarse, finger=replace(f, **{field: getattr(f, field) * math.exp(s)}))
                 for s in (-h, h))  # type: ignore[return-value]


def finger_tables(
    specs: Sequence[FieldSpec],
    cache_dir: str | os.PathLike,
    names: Sequence[str] = ("modulus", "radius"),
    *,
    workers: int | None = None,
    progress: bool = True,
    device: str | None = None,
    spacing_mm: tuple[float, float] = FINGER_FIELD_SPACING_MM,
    force_nodes: int = FINGER_FIELD_FORCE_NODES,
) -> dict[str, dict[tuple[float, ...], ModulusTable]]:
    """{name: {state: its table}} of the finger nuisances ``names`` for the fields ``specs``
    (one per state): the coarse fields of :func:`finger_field_specs`, all built on one cluster
    into ``cache_dir`` (``workers``, ``progress``, ``device`` as
    :func:`~ectskin.twin.field_build.build_fields`), differenced at their contact nodes."""
    pairs = [(name, spec, finger_field_specs(spec, name, spacing_mm=spacing_mm,
                                             force_nodes=force_nodes))
             for name in names for spec in specs]
    built = build_fields([s for _, _, two in pairs for s in two], cache_dir, workers=workers,
                         progress=progress, device=device)
    out: dict[str, dict[tuple[float, ...], ModulusTable]] = {name: {} for name in names}
    for i, (name, spec, _) in enumerate(pairs):
        small, big = built[2 * i], built[2 * i + 1]
        h = FINGER_STEPS[name]
        nodes = {face: small.grid(face) for face in small.faces}
        values = {face: (big.node_values(face, "contact") - small.node_values(face, "contact"))
                  / (2 * h) for face in small.faces}
        out[name][spec.inflation_ml] = ModulusTable(nodes, small.forces_n, values, h)
    return out
