"""Validation helpers shared by every module: user input is checked once, at the door.

Every check raises :class:`EctskinError` (a ``ValueError``) with a message that names where the
value came from (a file, a field, a frame), what was expected and what was found. Never use
``assert`` on user input.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np


class EctskinError(ValueError):
    """A clear, user-facing error about bad input (file, field, expected, found)."""


def where(source: str | None, field: str) -> str:
    """Format the location of a value, e.g. ``"layout.json: electrodes[3].width_mm"``."""
    return f"{source}: {field}" if source else field


def check_option(name: str, value: Any, allowed: Sequence[Any], source: str | None = None) -> Any:
    """Return ``value`` if it is one of ``allowed``, else raise a clear error."""
    if value not in allowed:
        allowed_s = ", ".join(repr(a) for a in allowed)
        raise EctskinError(
            f"Invalid value for {where(source, repr(name))}: allowed values are {allowed_s}; "
            f"got {value!r}"
        )
    return value


def check_type(name: str, value: Any, types: type | tuple[type, ...], source: str | None = None):
    """Return ``value`` if it is an instance of ``types``, else raise a clear error."""
    if not isinstance(value, types):
        names = (
            " or ".join(t.__name__ for t in types) if isinstance(types, tuple) else types.__name__
        )
        raise EctskinError(
            f"{where(source, name)} must be {names}, got {type(value).__name__} ({value!r:.60})"
        )
    return value


def check_array(
    name: str,
    value: Any,
    shape: tuple[int | None, ...],
    *,
    dtype: Any = np.float64,
    finite: bool = False,
    source: str | None = None,
) -> np.ndarray:
    """Convert ``value`` to an array of ``dtype`` and check its shape (``None`` = any size).

    With ``finite=True`` a NaN or inf is refused, naming the first offending index.
    """
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise EctskinError(
            f"{where(source, name)} must be numeric ({np.dtype(dtype).name}); {exc}"
        ) from None
    want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        raise EctskinError(f"{where(source, name)} must have shape {want}, got {arr.shape}")
    if finite and arr.size and not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise EctskinError(
            f"{where(source, name)} must be finite; found {arr[bad]} at index {bad}"
        )
    return arr


def parse_floats(name: str, text: str | Iterable[float], n: int | None = None) -> list[float]:
    """Parse ``"0,10,20"`` (or a sequence) into floats, optionally requiring ``n`` of them."""
    if isinstance(text, str):
        parts = [p.strip() for p in text.split(",") if p.strip()]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise EctskinError(
                f"{name} must be comma-separated numbers like '0,10,20', got {text!r}"
            ) from None
    else:
        values = [float(v) for v in text]
    if not values:
        raise EctskinError(f"{name} must hold at least one number, got {text!r}")
    if n is not None and len(values) != n:
        raise EctskinError(f"{name} must hold {n} numbers, got {len(values)} ({text!r})")
    return values


#: Seeds are integers from 0 to MAX_SEED: what numpy's generators, torch and scikit-learn all take.
MAX_SEED = 2**32 - 1


def check_seed(name: str, value: Any, source: str | None = None) -> int:
    """Return ``value`` if it is an integer from 0 to :data:`MAX_SEED`, else raise a clear error."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not (
        0 <= value <= MAX_SEED
    ):
        raise EctskinError(
            f"{where(source, name)} must be an integer from 0 to {MAX_SEED}, got {value!r}"
        )
    return int(value)
