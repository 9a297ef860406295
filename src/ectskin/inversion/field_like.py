"""The interface of a field that the inversion reads (:class:`FieldLike`): a
:class:`~ectskin.twin.field.ResponseField`, or an analytic model with the same methods (the
tests' flat skin)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np


class FieldSpecLike(Protocol):
    """What the inversion reads of a field's spec."""

    @property
    def inflation_ml(self) -> tuple[float, ...]: ...

    @property
    def force_range_n(self) -> tuple[float, float]: ...

    @property
    def height_range_mm(self) -> tuple[float, float]: ...

    def extent(self, face: str) -> tuple[tuple[float, float], tuple[float, float]]: ...


class FieldLike(Protocol):
    """The interface of :class:`~ectskin.twin.field.ResponseField` that the inversion uses (an
    analytic model with the same methods plugs in)."""

    @property
    def spec(self) -> Any: ...

    @property
    def faces(self) -> tuple[str, ...]: ...

    @property
    def n_pairs(self) -> int: ...

    @property
    def untouched(self) -> np.ndarray: ...

    @property
    def forces_n(self) -> np.ndarray: ...

    @property
    def heights_mm(self) -> np.ndarray: ...

    def grid(self, face: str) -> tuple[np.ndarray, np.ndarray]: ...

    def node_values(self, face: str, part: str = "contact") -> np.ndarray: ...

    def readout(self, face: str, u_mm: Any, v_mm: Any, force_n: Any, height_mm: Any = 0.0) -> np.ndarray: ...

    def jacobian(self, face: str, u_mm: Any, v_mm: Any, force_n: Any, height_mm: Any = 0.0) -> np.ndarray: ...
