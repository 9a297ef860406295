"""The error of a fit that leaves nuisances out of its model (the bound maps' ``fit`` case).

A field inversion estimates the finger's point and force and some nuisances, but models the
person's finger only as a scale on its signal, not its radius and pulp; those move the readouts
all the same. To first order (exactly for a linear model with Gaussian noise and priors) the
fit's error covariance is A⁻¹ + Σ_j s_j² g_j g_jᵀ: A the fit's Fisher information with its
priors, g_j = A⁻¹ J_fᵀ Σ⁻¹ J_j the shift one unit of left-out column j makes, s_j its spread.
Not a lower bound: what that fit reaches, the bound (:mod:`ectskin.twin.bound`) plus what its
model omits. :class:`FitModel` says what a fit estimates and leaves out; its ``error`` is one
point's from the bound's Jacobian (:func:`ectskin.twin.bound.point_bounds` with ``fit``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option
from ectskin.twin.bound import NUISANCE_NAMES, RCOND, ResponseProvider, crb


@dataclass(frozen=True)
class FitError:
    """The error of a fit whose model leaves columns out (:func:`fit_error`), parameters of
    interest in column order: ``std`` (k,) its bound with the columns it estimates (inf where
    unresolved), ``bias`` (k, m) the error one prior SD of each left-out column makes, and
    ``rms`` (k,) = sqrt(std² + Σ bias²)."""

    std: np.ndarray
    bias: np.ndarray
    rms: np.ndarray


def fit_error(
    J: np.ndarray,
    sigma: np.ndarray,
    *,
    left_out: Mapping[int, float],
    nuisance_cols: Sequence[int] = (),
    prior_var: Mapping[int, float] | None = None,
    rcond: float = RCOND,
) -> FitError:
    """The error of a penalised least-squares fit of the columns of ``J`` not in ``left_out``
    to readouts that every column moves (module docstring).

    ``left_out``: {column: its standard deviation in the data (> 0)}, columns the fit does not
    estimate; ``nuisance_cols`` and ``prior_var`` as in :func:`crb` (for the fitted columns).
    The parameters of interest are the columns in neither.
    """
    n = np.asarray(J).shape[1]
    out = {int(c): float(s) for c, s in left_out.items()}
    if not set(out) <= set(range(n)) or not all(np.isfinite(s) and s > 0 for s in out.values()):
        raise EctskinError(
            f"fit_error: left_out must map columns 0..{n - 1} to standard deviations > 0, got {left_out}"
        )
    if set(out) & {int(c) for c in nuisance_cols} or set(out) & {int(c) for c in (prior_var or {})}:
        raise EctskinError("fit_error: a left-out column cannot be fitted too (nuisance_cols, prior_var)")
    fitted = [c for c in range(n) if c not in out]
    pos = {c: i for i, c in enumerate(fitted)}
    var = {pos[int(c)]: v for c, v in (prior_var or {}).items()}
    b = crb(J[:, fitted], sigma, nuisance_cols=[pos[int(c)] for c in nuisance_cols],
            prior_var=var, rcond=rcond)
    interest = [i for i, c in enumerate(fitted) if c not in {int(x) for x in nuisance_cols}]
    # the fit's normal matrix with its priors (known columns, variance 0, out), scaled to unit
    # diagonal and inverted with the floor of _bound_block
    keep = [i for i in range(len(fitted)) if var.get(i, np.inf) != 0]
    s = np.asarray(sigma, dtype=np.float64)
    Jw = np.asarray(J, dtype=np.float64) / s[:, None]
    A = Jw[:, [fitted[i] for i in keep]].T @ Jw[:, [fitted[i] for i in keep]]
    for k, i in enumerate(keep):
        if np.isfinite(var.get(i, np.inf)):
            A[k, k] += 1.0 / var[i]
    d = np.sqrt(np.maximum(np.diag(A), 0.0))
    live = d > 0
    bias = np.zeros((len(interest), len(out)))
    if live.any():
        dl = d[live]
        lam, V = np.linalg.eigh(A[np.ix_(live, live)] / np.outer(dl, dl))
        inv = 1.0 / np.maximum(lam, rcond * lam[-1])
        M = (V * inv) @ V.T
        cols = np.asarray([fitted[i] for i in keep])[live]
        row = {fitted[i]: k for k, i in enumerate(np.asarray(keep)[live])}
        for j, (c, sd) in enumerate(sorted(out.items())):
            g = (Jw[:, cols].T @ Jw[:, c]) * sd
            x = (M @ (g / dl)) / dl
            for r, i in enumerate(interest):
                bias[r, j] = x[row[fitted[i]]] if fitted[i] in row else 0.0
    rms = np.sqrt(b.std**2 + np.sum(bias**2, axis=1))
    return FitError(b.std, bias, np.where(np.isfinite(b.std), rms, np.inf))


@dataclass(frozen=True)
class FitModel:
    """A fit that estimates some nuisances and leaves others out (the maps' ``fit`` case,
    :func:`fit_error`).

    nuisances : estimated alongside the point and force (with the maps' ``prior_sd``).
    left_out : in the readouts at their prior SD (``prior_sd``, which must give one), not
        estimated.
    scale_sd : the fit's own finger signal scale, (1 + a) Δ with Δ the readout less the
        provider's ``untouched()`` readout, a with this prior SD (None: no scale column).
    """

    nuisances: tuple[str, ...] = ("push", "inflation")
    left_out: tuple[str, ...] = ("finger", "modulus")
    scale_sd: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "nuisances", tuple(self.nuisances))
        object.__setattr__(self, "left_out", tuple(self.left_out))
        for k in (*self.nuisances, *self.left_out):
            check_option("nuisance", k, NUISANCE_NAMES)
        if set(self.nuisances) & set(self.left_out):
            raise EctskinError(
                f"FitModel: a nuisance is either fitted or left out, not both: "
                f"{sorted(set(self.nuisances) & set(self.left_out))}"
            )
        if self.scale_sd is not None and not (np.isfinite(self.scale_sd) and self.scale_sd > 0):
            raise EctskinError(f"FitModel: scale_sd must be > 0 or None, got {self.scale_sd!r}")

    def settings(self) -> dict[str, Any]:
        """What the fit is, as the maps' settings record it."""
        return asdict(self)

    def jacobian_nuisances(self, nuisances: Sequence[str]) -> list[str]:
        """The nuisances whose columns the Jacobian needs: ``nuisances``, then this fit's others."""
        return [*nuisances, *(k for k in (*self.nuisances, *self.left_out) if k not in nuisances)]

    def error(
        self,
        provider: ResponseProvider,
        c: np.ndarray,
        J: np.ndarray,
        cols: Mapping[str, slice],
        sigma: np.ndarray,
        prior: Mapping[str, float | None],
        rcond: float = RCOND,
    ) -> tuple[float, float]:
        """(position error sqrt(rms_u² + rms_v²) mm, force or height error) of this fit at one
        point whose readout is ``c`` and Jacobian ``J`` (columns ``cols`` after u, v and the
        third), noise ``sigma``; the left-out nuisances' spreads and the fitted ones' priors from
        ``prior``."""
        idx = lambda k: list(range(cols[k].start, cols[k].stop))  # noqa: E731
        sd = {k: float(v) for k, v in prior.items() if v is not None}
        use = [0, 1, 2] + [i for k in self.nuisances for i in idx(k)]
        var = {use.index(i): sd[k] ** 2 for k in self.nuisances if k in sd for i in idx(k)}
        left: dict[int, float] = {}
        for k in self.left_out:
            if k not in sd:
                raise EctskinError(f"fit case: the left-out nuisance {k!r} needs a prior SD (its spread)")
            left.update({i: sd[k] for i in idx(k)})
        Jf = J[:, use]
        if self.scale_sd is not None:
            untouched = getattr(provider, "untouched", None)
            if untouched is None:
                raise EctskinError(
                    f"fit case: a finger scale needs the provider's untouched() readout; "
                    f"{type(provider).__name__} has none"
                )
            var[Jf.shape[1]] = float(self.scale_sd) ** 2
            Jf = np.c_[Jf, c - np.asarray(untouched(), dtype=np.float64)]
        n_f = Jf.shape[1]
        lo = list(left)
        e = fit_error(np.c_[Jf, J[:, lo]], sigma, left_out={n_f + j: left[c_] for j, c_ in enumerate(lo)},
                      nuisance_cols=range(3, n_f), prior_var=var, rcond=rcond)
        return float(np.hypot(e.rms[0], e.rms[1])), float(e.rms[2])
