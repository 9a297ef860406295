"""The result of one frame's inversion and its standard errors (:mod:`ectskin.inversion.fit`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ectskin._check import EctskinError
from ectskin.inversion.finger_nuisance import finger_column
from ectskin.inversion.model import MODES, StateModel
from ectskin.twin.bound import crb, fisher_information


@dataclass(frozen=True)
class FingerEstimate:
    """One fitted finger: its face, whether it presses (``contact``) or hovers, its point
    (u, v) mm, force N (0 hovering), height mm (0 pressing), and their standard errors (the
    bound at the solution; 0 for the value the mode fixes, inf where unresolved); ``scale``
    1 + a, its signal's fitted relative size, and its standard error (1 and 0 without
    ``finger_scale_sd``); ``modulus_ln`` ln(E / E0) and ``radius_ln`` ln(R / R0), its pulp's
    modulus and its fingertip's radius against the field's finger, and their standard errors
    (0 and 0 without ``modulus`` / ``radius``, or hovering); ``point_se_noise_mm``
    √(σ_u² + σ_v²) of the readout noise alone, which says how well the frame tells this finger's
    point whatever ``bound_error`` adds to the standard errors above (which finger of a fit is
    the best located: :func:`~ectskin.pipeline.inversion.prediction_columns`)."""

    face: str
    contact: bool
    u_mm: float
    v_mm: float
    force_n: float
    height_mm: float
    u_se_mm: float
    v_se_mm: float
    force_se_n: float
    height_se_mm: float
    scale: float = 1.0
    scale_se: float = 0.0
    modulus_ln: float = 0.0
    modulus_ln_se: float = 0.0
    radius_ln: float = 0.0
    radius_ln_se: float = 0.0
    point_se_noise_mm: float = math.nan


@dataclass(frozen=True)
class InversionResult:
    """The inversion of one frame.

    ``n_fingers`` (0, 1 or 2) is the count chosen by BIC; ``fingers`` its estimates;
    ``log_likelihood`` and ``bic`` those of the chosen fit; ``bic_by_count`` the BIC of every
    count (index = count; inf where the count was not tried, see ``gate_p``); ``converged``
    whether the chosen fit's optimiser stopped on a tolerance (always True for no finger);
    ``nuisance`` the fitted nuisance coefficients by name; ``coupling`` the two fingers' fitted
    coupling ρ (:mod:`ectskin.inversion.coupling`; NaN unless two coupled fingers); ``fitted``
    the chosen fit's readout (n_pairs,) pF, NaN at the channels left out (masked), what the
    residual y − fitted is taken from (:mod:`ectskin.inversion.model_error`); ``leverage``
    each channel's leverage in that fit (the diagonal of the weighted hat matrix of its Jacobian
    at the solution, the priors' information added; NaN where left out): the share of a
    channel's variance the fit takes out of its residual.
    """

    n_fingers: int
    fingers: tuple[FingerEstimate, ...]
    log_likelihood: float
    bic: float
    converged: bool
    bic_by_count: tuple[float, ...]
    nuisance: dict[str, float] = field(default_factory=dict)
    coupling: float = math.nan
    # derived from the fit above; arrays, so left out of == (a result compares by its answer)
    fitted: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False, repr=False)
    leverage: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False, repr=False)


@dataclass
class Fit:
    """One fit of k fingers: their (face index, mode index, (u, v, s)), the nuisance
    coefficients β, its χ² (with the priors' terms), whether the optimiser converged, the
    coupling ρ, the fingers' relative scales a and their finger nuisances ({"modulus": ln(E / E0)
    per finger, "radius": ln(R / R0)}, NaN for a finger without them: hovering)."""

    fingers: list[tuple[int, int, np.ndarray]]  # (face index, mode index, x = (u, v, s))
    beta: np.ndarray
    chi2: float
    converged: bool
    rho: float = math.nan  # the two fingers' coupling (coupled two-finger fits)
    scales: np.ndarray = field(default_factory=lambda: np.zeros(0))  # each finger's a
    finger_nuisances: dict[str, np.ndarray] = field(default_factory=dict)  # name: per finger

    @property
    def n_params(self) -> int:
        return (3 * len(self.fingers) + (0 if math.isnan(self.rho) else 1) + self.beta.size
                + self.scales.size
                + sum(int(np.isfinite(v).sum()) for v in self.finger_nuisances.values()))


def build_result(m: StateModel, fit: Fit, w: int, ll: float, bics: list[float],
                 sigma: Callable[[StateModel, np.ndarray, int], np.ndarray],
                 point_sigma: Callable[[StateModel, np.ndarray, int], np.ndarray] | None = None
                 ) -> InversionResult:
    """The :class:`InversionResult` of the chosen fit: its fingers with their standard errors,
    the Cramér–Rao bound at the solution (:func:`ectskin.twin.bound.crb` of the model's Jacobian
    there, the nuisances estimated, the priors' information added); ``sigma(m, mu, w)`` is the
    noise at the fitted readout mu. ``point_sigma``: the spread of the readouts (the
    readout's noise and the field's model error, :mod:`ectskin.inversion.model_error`) that the
    standard errors of each finger's point, force and height carry instead, the fit weighted by
    ``sigma`` as it was (:func:`sandwich`); the scales' and finger nuisances' standard errors
    stay ``sigma``'s (what a person's pool reads)."""
    k = len(fit.fingers)
    ests: list[FingerEstimate] = []
    mu = m.untouched + m.N @ fit.beta
    nuisance_prior = {i: float(1.0 / pw**2) for i, pw in enumerate(m.prior_w) if pw > 0}
    if not k:
        hat = leverage(m.N, sigma(m, mu, w), nuisance_prior)
    else:
        cols, scale_cols = [], []
        g = 1.0 + fit.scales if fit.scales.size else np.ones(k)
        for j, (fi, mi, x) in enumerate(fit.fingers):
            d, dj = m.signal(m.faces[fi], MODES[mi], x)
            mu = mu + g[j] * d
            cols.append(g[j] * dj)
            scale_cols.append(d[:, None])
        ns = fit.scales.size
        extra = [(q, j, float(v[j])) for q, v in fit.finger_nuisances.items()
                 for j in range(k) if np.isfinite(v[j])]  # the order of the fit's parameters
        mod_cols, mod_w = [], []
        for q, j, e in extra:  # x M of each pressing finger: its slopes and its own column
            fi, _, x = fit.fingers[j]
            M, dM = finger_column(m, q, m.faces[fi], x)
            mu = mu + e * M
            cols[j] = cols[j] + e * dM
            mod_cols.append(M[:, None])
            mod_w.append(m.finger_columns[q][1])
        nm = len(extra)
        if not math.isnan(fit.rho):  # the coupling: its share, slopes and its own column
            keys = [(m.faces[fi], MODES[mi]) for fi, mi, _ in fit.fingers]
            c, da, db, drho = m.coupling(keys, [x for _, _, x in fit.fingers], fit.rho)
            mu = mu + c
            cols = [cols[0] + da, cols[1] + db, drho[:, None]]
        # the scales are bounded beside the fingers (the same marginal bound as nuisances)
        J = np.concatenate(cols, axis=1)
        n0 = J.shape[1]
        J = np.concatenate([J] + scale_cols[:ns] + mod_cols + [m.N], axis=1)
        prior = {n0 + ns + nm + i: var for i, var in nuisance_prior.items()}
        prior.update({n0 + i: float(1.0 / m.scale_w**2) for i in range(ns)})
        prior.update({n0 + ns + i: float(1.0 / mw**2) for i, mw in enumerate(mod_w)})
        interest = set(range(3 * k)) | set(range(n0, n0 + ns + nm))
        nuisance_cols = [c for c in range(J.shape[1]) if c not in interest]
        noise = sigma(m, mu, w)
        hat = leverage(J, noise, prior)
        b = crb(J, noise, prior_var=prior, nuisance_cols=nuisance_cols)
        point = b.std if point_sigma is None else sandwich(J, noise, point_sigma(m, mu, w),
                                                          prior, sorted(interest), b.resolved)
        for j, (fi, mi, x) in enumerate(fit.fingers):
            se = point[3 * j: 3 * j + 3]
            contact = MODES[mi] == "contact"
            h = 0.0 if contact else float(np.exp(x[2]))
            ests.append(FingerEstimate(
                face=m.faces[fi], contact=contact, u_mm=float(x[0]), v_mm=float(x[1]),
                force_n=float(x[2]) if contact else 0.0, height_mm=h,
                u_se_mm=float(se[0]), v_se_mm=float(se[1]),
                force_se_n=float(se[2]) if contact else 0.0,
                point_se_noise_mm=float(np.hypot(b.std[3 * j], b.std[3 * j + 1])),
                height_se_mm=0.0 if contact else h * float(se[2]),
                scale=float(g[j]), scale_se=float(b.std[3 * k + j]) if ns else 0.0,
                **{f"{q}_ln{end}": v for i, (q, jj, e) in enumerate(extra) if jj == j
                   for end, v in (("", e), ("_se", float(b.std[3 * k + ns + i])))},
            ))
    return InversionResult(
        n_fingers=k, fingers=tuple(ests), log_likelihood=ll, bic=bics[k],
        converged=fit.converged, bic_by_count=tuple(bics),
        nuisance={n: float(v) for n, v in zip(m.nuisance_names, fit.beta)},
        coupling=fit.rho, fitted=mu, leverage=hat,
    )


def sandwich(J: np.ndarray, sigma: np.ndarray, spread: np.ndarray, prior_var: dict[int, float],
             cols: list[int], resolved: np.ndarray) -> np.ndarray:
    """The standard errors of the parameters ``cols`` of a fit weighted by ``sigma`` (W = σ⁻²)
    whose readouts scatter by ``spread`` (V = spread², the noise and the model error) instead:
    √diag(A⁻¹ B A⁻¹), A = Jᵀ W J + P, B = Jᵀ W V W J + P (P the priors' precisions, the priors
    as pseudo-observations of their own variance), the fit's covariance as it was weighted
    (the sandwich; the bound of ``spread`` alone, Jᵀ V⁻¹ J, is its least, reached only where
    the weights are V's). Inf where the plain bound has the column ``resolved`` False.
    ``prior_var``: {column: variance > 0}, inf for none (a known column is left out of ``J``)."""
    if any(not var > 0 for var in prior_var.values()):
        raise EctskinError(f"sandwich: prior variances must be > 0, got {prior_var}")
    A = _information(J, sigma, prior_var)
    Jv = J * (spread / sigma**2)[:, None]
    B = _information(Jv, np.ones(J.shape[0]), prior_var)
    try:  # the rows of A⁻¹ asked for (A is the fit's information: symmetric, positive)
        Ai = np.linalg.solve(A, np.eye(A.shape[0])[:, cols]).T
    except np.linalg.LinAlgError:  # singular: the unresolved columns are inf below
        Ai = np.linalg.pinv(A, rcond=1e-13, hermitian=True)[cols]
    std = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Ai, B, Ai), 0.0))
    return np.where(resolved, std, np.inf)


def leverage(J: np.ndarray, sigma: np.ndarray, prior_var: dict[int, float]) -> np.ndarray:
    """The diagonal of the hat matrix W½ J (Jᵀ W J + P)⁻¹ Jᵀ W½ of a fit with Jacobian ``J``
    (channels, parameters), noise ``sigma`` (W = σ⁻²) and Gaussian priors ``prior_var``
    {column: variance} (P: their precisions): each channel's leverage, in [0, 1]."""
    A = _information(J, sigma, prior_var)
    Jw = J / sigma[:, None]
    X = np.linalg.lstsq(A, Jw.T, rcond=None)[0] if Jw.shape[1] else np.zeros((0, J.shape[0]))
    return np.clip(np.einsum("ij,ji->i", Jw, X), 0.0, 1.0)


def _information(J: np.ndarray, sigma: np.ndarray, prior_var: dict[int, float]) -> np.ndarray:
    """Jᵀ W J + P (:func:`~ectskin.twin.bound.fisher_information`, its inputs checked) with the
    precisions P of the finite priors ``prior_var`` {column: variance > 0} on its diagonal."""
    A = fisher_information(J, sigma)
    for c, var in prior_var.items():
        if var > 0 and np.isfinite(var):
            A[c, c] += 1.0 / var
    return A
