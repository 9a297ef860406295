"""Trained scores over seeds: mean ± a Student-t confidence interval, and the paired comparison
of a layout with the paper's.

A trained score (:func:`~ectskin.design.score.score_layout`) depends on its seed: the protocol's
draws (touch points, forces, noise), the split and the models' initialisation. With the same seed
every layout sees the same touches (the trial plan depends on the scoring regions, not on the
electrodes), so layout A and the paper's layout scored with seeds s_1 … s_n give n paired
differences d_i = A_i − paper_i on the same test touches. Their mean and the t-interval
mean ± t_{n−1, (1+level)/2} · sd / sqrt(n) (the seeds are the independent replicates) say by how
much A differs from the paper; A is called better (or worse) only when that interval excludes
zero.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ectskin._check import EctskinError

#: the trained metrics aggregated over seeds, and whether lower is better
METRICS: dict[str, bool] = {
    "loc_mm_mean": True,
    "loc_mm_median": True,
    "loc_mm_p90": True,
    "face_accuracy": False,
    "region_accuracy": False,
    "force_mae_n": True,
    "track_ad_mm": True,
}
LEVEL = 0.95


def t_interval(values: Sequence[float | None], level: float = LEVEL) -> dict[str, Any]:
    """Mean and the two-sided Student-t interval of the mean of ``values`` (independent draws);
    ``n``, ``sd`` (n − 1 in the denominator). One value: the interval is (−inf, inf) (no spread
    to estimate); a None or NaN value is an error naming it."""
    if not 0 < level < 1:
        raise EctskinError(f"t_interval: level must be in (0, 1), got {level!r}")
    if any(v is None for v in values):
        raise EctskinError(f"t_interval: a value is missing (None) in {list(values)!r}")
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size == 0 or not np.all(np.isfinite(x)):
        raise EctskinError(f"t_interval: expected one or more finite numbers, got {list(values)!r}")
    n, mean = x.size, float(x.mean())
    if n == 1:
        return {"n": 1, "mean": mean, "sd": None, "ci": [-np.inf, np.inf], "level": level}
    from scipy.stats import t

    sd = float(x.std(ddof=1))
    half = float(t.ppf(0.5 + level / 2, n - 1)) * sd / np.sqrt(n)
    return {"n": n, "mean": mean, "sd": sd, "ci": [mean - half, mean + half], "level": level}


def paired_comparison(
    a: Sequence[float], b: Sequence[float], *, lower_is_better: bool = True, level: float = LEVEL
) -> dict[str, Any]:
    """The t-interval of the paired differences ``a − b`` (same seeds, same order) and the
    verdict on ``a``: ``better`` / ``worse`` when the interval excludes zero, else
    ``not shown``."""
    if len(a) != len(b):
        raise EctskinError(
            f"paired_comparison: the two layouts need the same seeds, got {len(a)} and {len(b)} "
            f"values"
        )
    d = t_interval([x - y for x, y in zip(a, b)], level)
    lo, hi = d["ci"]
    if lo > 0 or hi < 0:
        lower = hi < 0
        verdict = "better" if lower == lower_is_better else "worse"
    else:
        verdict = "not shown"
    return {"difference": d, "verdict": verdict}


def aggregate(per_seed: Mapping[int, Mapping[str, Any]], level: float = LEVEL) -> dict[str, Any]:
    """Per trained metric of :data:`METRICS` over the seeds' scores (``{seed: score}``): its
    ``values`` and ``seeds``, ``mean`` and ``ci`` (None where a seed has no value)."""
    seeds = sorted(per_seed)
    out: dict[str, Any] = {}
    for m in METRICS:
        vals = [per_seed[s].get(m) for s in seeds]
        if all(v is None for v in vals):
            continue
        entry: dict[str, Any] = {"seeds": seeds, "values": vals, "mean": None, "ci": None}
        if all(v is not None for v in vals):
            t = t_interval([float(v) for v in vals if v is not None], level)
            entry.update(mean=t["mean"], ci=t["ci"], sd=t["sd"])
        out[m] = entry
    return out


def compare_with(
    per_seed: Mapping[int, Mapping[str, Any]],
    reference: Mapping[int, Mapping[str, Any]],
    level: float = LEVEL,
) -> dict[str, Any]:
    """{metric: :func:`paired_comparison` of the layout's seeds against the reference's} over
    the seeds both have a value for (at least two)."""
    out = {}
    for m, lower in METRICS.items():
        seeds = [
            s for s in sorted(per_seed)
            if s in reference and per_seed[s].get(m) is not None and reference[s].get(m) is not None
        ]
        if len(seeds) < 2:
            continue
        out[m] = {
            "seeds": seeds,
            **paired_comparison(
                [per_seed[s][m] for s in seeds], [reference[s][m] for s in seeds],
                lower_is_better=lower, level=level,
            ),
        }
    return out


#: the issue's goal for a proposal: at most this many electrodes, a worst-case position bound at
#: most this share of the paper's, and a trained localisation error shown lower than the paper's
GOAL_MAX_ELECTRODES = 8
GOAL_BOUND_SHARE = 0.5
#: the rank agreement asked of the two scores (Spearman's rho at least this)
AGREEMENT_RHO = 0.7
#: resamples of the seeds behind the rank agreement's interval, and their generator's seed
BOOTSTRAP_DRAWS = 2000
BOOTSTRAP_SEED = 0


def _spearman(a: np.ndarray, b: np.ndarray) -> float | None:
    """Spearman's rho of two score vectors (ties: mean ranks); None where one ties them all."""
    from scipy.stats import rankdata

    ra, rb = rankdata(a), rankdata(b)
    if np.ptp(ra) == 0 or np.ptp(rb) == 0:
        return None
    return float(np.corrcoef(ra, rb)[0, 1])


def _per_seed(layouts: Sequence[Mapping[str, Any]], names: Sequence[str]) -> np.ndarray | None:
    """(layouts, seeds) trained mean localisation errors of ``names``, where every one was
    scored with the same two or more seeds (``trained.loc_mm_mean``); else None."""
    by_name = {e["name"]: e for e in layouts}
    rows, seeds = [], None
    for n in names:
        t = (by_name[n].get("trained") or {}).get("loc_mm_mean") or {}
        vals, got = t.get("values"), t.get("seeds")
        if not vals or got is None or any(v is None for v in vals):
            return None
        if seeds is None:
            seeds = list(got)
        elif list(got) != seeds:
            return None
        rows.append([float(v) for v in vals])
    if seeds is None or len(seeds) < 2:
        return None
    return np.asarray(rows)


def seed_agreement(info: Sequence[float], per_seed: np.ndarray, level: float = LEVEL
                   ) -> dict[str, Any]:
    """How well the trained ranking is resolved by its seeds, beside the information score
    ``info`` (one per layout; inf ranks worst) and the trained scores ``per_seed`` (layouts,
    seeds), the same seeds for every layout:

    * ``rho_ci``: the ``level`` percentile interval of Spearman's rho between ``info`` and the
      trained mean over seeds resampled with replacement (:data:`BOOTSTRAP_DRAWS`, every layout
      the same resample: a seed's test touches are every layout's), None where no resample
      ranks;
    * ``seed_to_seed_rho``: the mean over pairs of seeds of the rho between their trained
      rankings: how far one seed's ranking says the next one's. A trained ranking that its own
      seeds do not repeat cannot be matched by any score more closely than they match each
      other.
    """
    x = np.asarray(info, dtype=np.float64)
    v = np.asarray(per_seed, dtype=np.float64)
    n = v.shape[1]
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    draws = [_spearman(x, v[:, rng.integers(0, n, n)].mean(axis=1))
             for _ in range(BOOTSTRAP_DRAWS)]
    got = np.array([r for r in draws if r is not None])
    pairs = [_spearman(v[:, i], v[:, j]) for i in range(n) for j in range(i + 1, n)]
    pairs_ok = [r for r in pairs if r is not None]
    tail = 50 * (1 - level)
    return {
        "rho_ci": ([float(np.percentile(got, tail)), float(np.percentile(got, 100 - tail))]
                   if got.size else None),
        "level": level,
        "n_seeds": int(n),
        "seed_to_seed_rho": float(np.mean(pairs_ok)) if pairs_ok else None,
    }


def rank_agreement(
    layouts: Sequence[Mapping[str, Any]], key: str = "bound_mm_p95"
) -> dict[str, Any] | None:
    """Spearman's rank correlation between an information score (``key``: the worst-case
    position bound ``bound_mm_p95`` by default, or ``fit_error_mm_p95``; None, an unresolved
    point, ranks as the worst) and the trained score's mean localisation error (``loc_mm_mean``)
    over the layouts that have both (ties get their mean rank). None with fewer than 3 such
    layouts (no ranking to compare). Where each layout's trained score holds the same two or more
    seeds, ``seeds`` says how well they resolve the ranking (:func:`seed_agreement`: rho's
    interval over resampled seeds, and the trained rankings' own seed-to-seed rho)."""
    both = [
        (e["name"], np.inf if e[key] is None else float(e[key]), float(e["loc_mm_mean"]))
        for e in layouts
        if key in e and e.get("loc_mm_mean") is not None
    ]
    if len(both) < 3:
        return None
    info = np.array([b for _, b, _ in both])
    rho = _spearman(info, np.array([t for _, _, t in both]))  # None: one score ties them all
    out = {
        "key": key,
        "rho": rho,
        "n": len(both),
        "layouts": [n for n, _, _ in both],
        "agree": rho is not None and rho >= AGREEMENT_RHO,
        "threshold": AGREEMENT_RHO,
    }
    per_seed = _per_seed(layouts, out["layouts"])
    if rho is not None and per_seed is not None:
        out["seeds"] = seed_agreement(info, per_seed)
    return out


def goal_layouts(layouts: Sequence[Mapping[str, Any]], paper: str = "paper") -> dict[str, Any]:
    """Which layouts meet the issue's goal against the layout named ``paper``: at most
    :data:`GOAL_MAX_ELECTRODES` electrodes, ``bound_mm_p95`` at most :data:`GOAL_BOUND_SHARE` of
    the paper's, and a ``better`` paired verdict on ``loc_mm_mean`` (its interval excludes zero).
    ``met`` lists them; ``half_bound`` the layouts meeting the first two only."""
    ref = next((e for e in layouts if e["name"] == paper), None)
    ref_p95 = None if ref is None else ref.get("bound_mm_p95")
    half, met = [], []
    for e in layouts:
        if e["name"] == paper or ref_p95 is None or e.get("bound_mm_p95") is None:
            continue
        if e["n_electrodes"] <= GOAL_MAX_ELECTRODES and (
            e["bound_mm_p95"] <= GOAL_BOUND_SHARE * ref_p95
        ):
            half.append(e["name"])
            verdict = e.get("vs_paper", {}).get("loc_mm_mean", {}).get("verdict")
            if verdict == "better":
                met.append(e["name"])
    return {
        "paper_bound_mm_p95": ref_p95,
        "max_electrodes": GOAL_MAX_ELECTRODES,
        "bound_share": GOAL_BOUND_SHARE,
        "half_bound": half,
        "met": met,
    }


__all__ = [
    "AGREEMENT_RHO",
    "LEVEL",
    "METRICS",
    "aggregate",
    "compare_with",
    "goal_layouts",
    "paired_comparison",
    "rank_agreement",
    "seed_agreement",
    "t_interval",
]
