"""One Levenberg–Marquardt fit of k fingers and the nuisances from a start
(:class:`~ectskin.inversion.fit.Inversion`'s counts and starts call it).

The parameters: each finger's (u, v, s) (s: force, or ln height), the coupling ρ of two
coupled fingers, each finger's relative signal scale a (``finger_scale_sd``), each pressing
finger's pulp modulus x = ln(E / E0) and radius ln(R / R0) (``modulus``, ``radius``:
:mod:`ectskin.inversion.finger_nuisance`), then the nuisance coefficients β. The model of the
channels is Σ_k ((1 + a_k) Δ_k + Σ_q x_kq M_kq) (+ the coupling's share) + N β.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from scipy.optimize import leastsq

from ectskin.inversion.coupling import RHO_MAX
from ectskin.inversion.finger_nuisance import FINGER_BOUND_SD, finger_column, nuisance_fingers
from ectskin.inversion.model import MODES, StateModel
from ectskin.inversion.result import Fit

#: the coupling ρ a two-finger fit starts from
RHO_START = 0.2
#: the penalty residual per unit (mm, N, ln mm) a parameter lies outside the field's range
BOUND_WEIGHT = 1e4
#: the most residual evaluations of one Levenberg–Marquardt fit
MAX_NFEV = 50
#: the optimiser's tolerances (MINPACK's lmder; its scaling by the Jacobian's column norms,
#: ``diag=None``, is ``least_squares``' ``x_scale="jac"``)
LM_OPTIONS: dict[str, Any] = {"ftol": 1e-6, "xtol": 1e-6, "gtol": 1e-8}
#: the scale's range: this many prior sd either side of 1 (a truncated Gaussian prior)
SCALE_BOUND_SD = 3.0
#: lmder's exit codes that mean it stopped on a tolerance (5: the evaluation budget ran out)
LM_CONVERGED = (1, 2, 3, 4)


def fit_fingers(m: StateModel, delta: np.ndarray, sigma: np.ndarray,
                start: list[tuple[int, int, np.ndarray]], coupled: bool = False,
                max_nfev: int = MAX_NFEV) -> Fit:
    """Levenberg–Marquardt over (x_1, …, x_k, [ρ], [a_1, …, a_k], [x_E of each pressing
    finger], β) from ``start`` (ρ: two coupled fingers; a: the fingers' scales, with
    ``m.scale_w``; x_E: the pulp moduli, and radii, with ``m.finger_columns``).

    The bounds (the field's ranges, ρ in [0, RHO_MAX], a and x_E within ``SCALE_BOUND_SD`` and
    ``FINGER_BOUND_SD`` prior sd) hold by evaluating the model at the parameters clipped into
    them and adding a stiff penalty residual ``BOUND_WEIGHT`` × (p − clip(p)): MINPACK's LM
    (``method="lm"``) takes no bounds, and costs a fraction of the bounded solvers' per
    iteration. The result is clipped into the ranges. ``max_nfev``: the most residual
    evaluations (``converged`` says whether it stopped on a tolerance before).
    """
    k = len(start)
    keys = [(m.faces[fi], MODES[mi]) for fi, mi, _ in start]
    with_rho = coupled and k == 2
    nx = 3 * k + int(with_rho)  # the fingers' (and ρ's) parameters
    nb, n = m.N.shape[1], m.n_pairs
    sw = m.scale_w
    ns = k if sw > 0 else 0  # each finger's relative scale a: (1 + a) Δ
    mod = nuisance_fingers(m, keys)  # the pressing fingers' pulp x_E (and radius): + x_E M
    names = list(m.finger_columns)
    nm = len(mod) * len(names)  # per nuisance, per pressing finger
    mws = np.repeat([m.finger_columns[q][1] for q in names], len(mod))
    # the priors' centres: 0 for the scales, the finger nuisances' (0 unless set)
    centre = np.concatenate([np.zeros(ns), np.repeat(
        np.array([m.finger_centre.get(q, 0.0) for q in names], dtype=np.float64), len(mod))])
    nr = ns + nm  # the priors' rows of the finger nuisances
    na = nx + nr  # the bounded parameters
    Nw = m.N / sigma[:, None]
    a_max = SCALE_BOUND_SD / sw if ns else 0.0
    e_max = FINGER_BOUND_SD / mws if nm else np.zeros(0)
    lo = np.concatenate([m.bounds[key][0] for key in keys]
                        + [np.zeros(int(with_rho)), np.full(ns, -a_max), centre[ns:] - e_max])
    hi = np.concatenate([m.bounds[key][1] for key in keys]
                        + [np.full(int(with_rho), RHO_MAX), np.full(ns, a_max),
                           centre[ns:] + e_max])
    # rows: the channels, the range penalties, the scales', the moduli's and the nuisances'
    # priors; the Jacobian's constant parts (the nuisance columns, the priors) are set once
    J = np.zeros((n + na + nr + nb, na + nb))
    J[:n, na:] = -Nw
    J[n + na: n + na + ns, nx: nx + ns] = sw * np.eye(ns)
    J[n + na + ns: n + na + nr, nx + ns: na] = np.diag(mws)
    J[n + na + nr:, na:] = np.diag(m.prior_w)
    cache: dict[str, Any] = {"p": None}
    diag = np.arange(na)
    neg_inv_sigma = (-1.0 / sigma)[:, None]
    prior_rows = np.concatenate([np.full(ns, sw), mws])

    def evaluate(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if cache["p"] is None or not (cache["p"] == p).all():
            x = p[:na]
            xc = np.clip(x, lo, hi)
            inside = x == xc
            total = np.zeros(n)
            for j, key in enumerate(keys):
                d, dj = m.signal(key[0], key[1], xc[3 * j: 3 * j + 3])
                g = 1.0 + xc[nx + j] if ns else 1.0
                total += g * d
                J[:n, 3 * j: 3 * j + 3] = (g * dj) * neg_inv_sigma
                if ns:
                    J[:n, nx + j] = d * neg_inv_sigma[:, 0]
            i = nx + ns
            for q in names:
                for j in mod:
                    M, dM = finger_column(m, q, keys[j][0], xc[3 * j: 3 * j + 3])
                    e = xc[i]
                    total += e * M
                    J[:n, 3 * j: 3 * j + 3] += (e * dM) * neg_inv_sigma
                    J[:n, i] = M * neg_inv_sigma[:, 0]
                    i += 1
            if with_rho:
                c, da, db, drho = m.coupling(keys, [xc[:3], xc[3:6]], float(xc[6]))
                total += c
                J[:n, 0:3] += da * neg_inv_sigma
                J[:n, 3:6] += db * neg_inv_sigma
                J[:n, 6] = drho * neg_inv_sigma[:, 0]
            if not inside.all():  # beyond a range: the model is flat there, the penalty not
                J[:n, :na][:, ~inside] = 0.0
            J[n + diag, diag] = np.where(inside, 0.0, BOUND_WEIGHT)
            r = np.concatenate([(delta - total) / sigma - Nw @ p[na:], BOUND_WEIGHT * (x - xc),
                                prior_rows * (xc[nx:] - centre), m.prior_w * p[na:]])
            cache.update(p=p.copy(), r=r, J=J.copy())
        return cache["r"], cache["J"]

    x0 = np.concatenate([x for _, _, x in start]
                        + [np.full(int(with_rho), RHO_START), centre])
    x0 = np.clip(x0, lo, hi)
    r0 = evaluate(np.concatenate([x0, np.zeros(nb)]))[0][:n]
    # the linear parameters (the scales, the moduli and β) from a linear fit at the start (the
    # priors' centres), with their priors, so that the optimiser begins near its valley
    A = np.vstack([np.hstack([-J[:n, nx:na], Nw]),
                   np.diag(np.concatenate([prior_rows, m.prior_w]))])
    lin = (np.linalg.lstsq(A, np.concatenate([r0, np.zeros(nr + nb)]), rcond=None)[0] if nr + nb
           else np.zeros(0))
    x0[nx:] = np.clip(x0[nx:] + lin[:nr], lo[nx:], hi[nx:])
    beta0 = lin[nr:]
    with warnings.catch_warnings():  # out of evaluations: `converged` says so
        warnings.simplefilter("ignore", RuntimeWarning)
        p, status = leastsq(
            lambda p: evaluate(p)[0], np.concatenate([x0, beta0]),
            Dfun=lambda p: evaluate(p)[1], maxfev=max_nfev, **LM_OPTIONS,
        )
    p = np.array(p, dtype=np.float64, ndmin=1)
    p[:na] = np.clip(p[:na], lo, hi)
    res = evaluate(p)[0]
    r = np.concatenate([res[:n], res[n + na:]])  # the channels and the priors
    fingers = [(fi, mi, p[3 * j: 3 * j + 3].copy()) for j, (fi, mi, _) in enumerate(start)]
    extra = {}
    for i, q in enumerate(names):
        extra[q] = np.full(k, math.nan)
        extra[q][mod] = p[nx + ns + i * len(mod): nx + ns + (i + 1) * len(mod)]
    return Fit(fingers, p[na:].copy(), float(r @ r), status in LM_CONVERGED,
               rho=float(p[6]) if with_rho else math.nan, scales=p[nx: nx + ns].copy(),
               finger_nuisances=extra)
