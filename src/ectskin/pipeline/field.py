"""The response fields of the reproduction's contact experiment: built once, cached, read by the
simulation (``Protocol.response="field"``, :mod:`ectskin.twin.field_response`).

One field per inflation state of :meth:`~ectskin.pipeline.config.ReproduceConfig.contact_protocol`
(:func:`contact_field_specs`), built on Dask by :func:`ectskin.twin.field_build.build_fields`
into the field cache (:func:`field_cache_dir`): ``ReproduceConfig.field_cache``, else
``$ECTSKIN_CACHE/fields``, else ``~/.cache/ectskin/fields`` (``$XDG_CACHE_HOME`` if set). A
field is keyed by everything it depends on (its spec and the physics code), so the cache is
shared by every output folder and a field is solved once per machine.

The spec: the simulation's layout, body and permittivities, the protocol's finger and force
range, both faces, the hover heights up to ``hover_max_mm``, on a named grid
(:data:`~ectskin.twin.field_spec.FIELD_GRIDS`: ``ReproduceConfig.field_grid``, "quick" by
default) through :func:`~ectskin.twin.field_spec.contact_field_spec`. Only the fingers' signal
comes from the field, the untouched readouts are the simulation's own (docs/contact.md says
what the coarse mesh costs).
"""

from __future__ import annotations

import os
from pathlib import Path

from ectskin._check import EctskinError, check_option
from ectskin.layout import SensorLayout, default_layout
from ectskin.twin.field import ResponseField
from ectskin.twin.field_build import build_fields, field_dir
from ectskin.twin.field_spec import FIELD_GRIDS, FieldGrid, FieldSpec, contact_field_spec
from ectskin.twin.finger import Finger
from ectskin.twin.protocol import Protocol

#: the environment variable naming ectskin's cache folder (fields go to its ``fields``)
CACHE_ENV = "ECTSKIN_CACHE"

def field_cache_dir(cache_dir: str | os.PathLike | None = None) -> Path:
    """Where response fields are cached: ``cache_dir``, else ``$ECTSKIN_CACHE/fields``, else
    ``$XDG_CACHE_HOME/ectskin/fields``, else ``~/.cache/ectskin/fields``."""
    if cache_dir is not None:
        return Path(os.fspath(cache_dir))
    root = os.environ.get(CACHE_ENV)
    if root:
        return Path(root) / "fields"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "ectskin" / "fields"


def protocol_field_specs(
    protocol: Protocol, layout: SensorLayout | None = None, grid: str | FieldGrid = "quick",
    states=None,
) -> list[FieldSpec]:
    """One field spec per inflation state of ``protocol`` (or of ``states``) on ``layout``
    (default: the paper's) and the default body, as the reproduction and ``ectskin simulate``
    simulate them, on ``grid``: a name of :data:`~ectskin.twin.field_spec.FIELD_GRIDS` or a
    grid."""
    if not isinstance(protocol, Protocol):
        raise EctskinError(f"protocol must be a Protocol, got {type(protocol).__name__}")
    if not isinstance(grid, FieldGrid):
        check_option("field grid", grid, tuple(FIELD_GRIDS))
        grid = FIELD_GRIDS[grid]
    layout = layout or default_layout()
    finger = Finger(radius_mm=protocol.finger_radius_mm)
    return [
        contact_field_spec(
            layout, state, grid, finger=finger,
            force_range_n=protocol.force_range_n,
            height_range_mm=(0.5, max(protocol.hover_max_mm, 1.0)),
        )
        for state in (protocol.states() if states is None else states)
    ]


def contact_field_specs(config) -> list[FieldSpec]:
    """The field specs of ``config``'s contact experiment (empty with a given recording)."""
    protocol = config.contact_protocol()
    return [] if protocol is None else protocol_field_specs(protocol, grid=config.field_grid)


def physics_field_specs(config) -> list[FieldSpec]:
    """The field specs the bound and the inversion read: the contact experiment's
    (:func:`contact_field_specs`), and with ``config.field_states == "all"`` also those of the
    paper experiment's states that it lacks (the contact run's data hold both), built alike
    (the contact protocol's finger, force and height ranges; the same grid)."""
    specs = contact_field_specs(config)
    if not specs or config.field_states != "all":
        return specs
    have = {s.inflation_ml for s in specs}
    contact, paper = config.contact_protocol(), config.simulation_protocol()
    extra = [s for s in paper.states() if tuple(float(x) for x in s) not in have]
    if not extra:
        return specs
    return specs + protocol_field_specs(contact, grid=config.field_grid, states=extra)


def contact_fields(
    config,
    cache_dir: str | os.PathLike | None = None,
    *,
    workers: int | None = None,
    progress: bool | None = None,
    specs: list[FieldSpec] | None = None,
) -> dict[tuple[float, ...], ResponseField]:
    """The response fields of ``config``'s contact experiment (or of ``specs``), state → field:
    read from the cache (``cache_dir``, else ``config.field_cache``, else
    :func:`field_cache_dir`), the missing ones built there on a Dask LocalCluster of
    ``workers`` (default ``config.workers``)."""
    specs = contact_field_specs(config) if specs is None else specs
    if not specs:
        return {}
    root = field_cache_dir(cache_dir if cache_dir is not None else config.field_cache)
    built = build_fields(
        specs, root,
        workers=config.workers if workers is None else workers,
        progress=config.progress if progress is None else progress,
    )
    return {s.inflation_ml: f for s, f in zip(specs, built)}


def contact_field_dirs(
    config, cache_dir: str | os.PathLike | None = None
) -> dict[tuple[float, ...], Path]:
    """State → cache folder of each contact field (what the simulation's workers read)."""
    root = field_cache_dir(cache_dir if cache_dir is not None else config.field_cache)
    return {s.inflation_ml: field_dir(s, root) for s in contact_field_specs(config)}
