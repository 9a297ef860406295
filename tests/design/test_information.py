"""The information score (ectskin.design.information): its bound maps against the closed-form
Fisher information of a point-charge model of a hand-built layout, its ambiguity against a
double loop, its determinism (runs and Dask worker counts) on the twin, and its bad input."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace

import numpy as np
import pytest
from point_charge_model import (  # tests/design/point_charge_model.py
    CONFIG,
    PointChargeResponse,
    closed_form_bounds,
    closed_form_fit_error,
    point_charges,
    two_wire_layout,
)

from ectskin._check import EctskinError
from ectskin.design.information import (
    INFORMATION_FILE,
    InformationConfig,
    ambiguity,
    finished_information,
    information_layout,
    information_score,
)
from ectskin.twin.readout import ReadoutConfig, noise_pf


@pytest.fixture(scope="module")
def analytic():
    layout = two_wire_layout()
    return layout, information_score(layout, CONFIG, providers=point_charges)


def test_the_bound_maps_are_the_closed_form_fisher_information(analytic):
    layout, score = analytic
    assert layout.n_electrodes == 4 and layout.n_pairs == 6 and score["case"] == "inflation"
    maps = score["maps"]
    pos_all, force_all = [], []
    for si, state in enumerate(CONFIG.states_ml):
        prov = PointChargeResponse(layout, state)
        for face, m in maps["states"][si]["faces"].items():
            got = m["contact"]["inflation"]
            for (iv, v), (iu, u) in itertools.product(enumerate(m["v_mm"]), enumerate(m["u_mm"])):
                pos, force = closed_form_bounds(prov, face, (u, v))
                # central differences of 0.25 mm and 0.05 N: the bounds within 0.6 % (measured
                # 0.23 % and 0.14 %)
                assert got["position_mm"][iv, iu] == pytest.approx(pos, rel=6e-3)
                assert got["force_n"][iv, iu] == pytest.approx(force, rel=6e-3)
                pos_all.append(pos)
                force_all.append(force)
    pos_all, force_all = np.array(pos_all), np.array(force_all)
    assert len(pos_all) == 2 * 2 * 4 * 11  # states x faces x (4 x 11 cells of 10 mm)
    assert score["bound_mm_mean"] == pytest.approx(pos_all.mean(), rel=1e-2)
    assert score["bound_mm_p95"] == pytest.approx(np.percentile(pos_all, 95), rel=1e-2)
    share = np.mean(force_all < 0.1)
    assert 0.05 < share < 0.95  # the threshold cuts through this model's force bounds
    # a share is a count: a point within the tolerance of the threshold could flip it; none is
    assert np.min(np.abs(force_all / 0.1 - 1)) > 6e-3
    assert score["force_observable_share"] == pytest.approx(share)


def test_the_fit_error_is_the_closed_form_error_of_a_fit_that_leaves_the_inflation_out(analytic):
    """The fit's maps against the point-charge model's closed form (A⁻¹ plus each left-out
    column's shift), the summary's keys against the maps, and the fit above the bound."""
    layout, score = analytic
    maps = score["maps"]
    got, want = [], []
    for si, state in enumerate(CONFIG.states_ml):
        prov = PointChargeResponse(layout, state)
        for face, m in maps["states"][si]["faces"].items():
            fit = np.asarray(m["contact"]["fit"]["position_mm"])
            for (iv, v), (iu, u) in itertools.product(enumerate(m["v_mm"]), enumerate(m["u_mm"])):
                got.append(fit[iv, iu])
                want.append(closed_form_fit_error(prov, face, (u, v)))
                bound = m["contact"]["inflation"]["position_mm"][iv, iu]
                assert fit[iv, iu] >= bound * (1 - 1e-9)  # leaving out never beats estimating
    got, want = np.array(got), np.array(want)
    np.testing.assert_allclose(got, want, rtol=6e-3)  # central differences, as the bound's
    assert got.max() > 2 * got.min()  # a map, not one number
    assert score["fit_error_mm_mean"] == pytest.approx(want.mean(), rel=1e-2)
    assert score["fit_error_mm_p95"] == pytest.approx(np.percentile(want, 95), rel=1e-2)
    assert score["fit_error_mm_median"] == pytest.approx(np.median(want), rel=1e-2)
    assert score["fit_error_mm_mean"] > 1.2 * score["bound_mm_mean"]  # the inflation costs here


def test_the_nuisance_and_its_prior_matter_in_this_model(analytic):
    """The closed form above would not match a score that dropped the nuisance or its prior."""
    layout, _ = analytic
    prov = PointChargeResponse(layout, (0, 0, 0))
    uv = (-15.0, 30.0)
    with_prior = closed_form_bounds(prov, "front", uv)[0]
    J = prov.jacobian("front", uv)
    s = noise_pf(prov.readout("front", [uv], [1.0], [0.0])[0], ReadoutConfig())
    fim = (J / s[:, None]).T @ (J / s[:, None])
    known = np.linalg.inv(fim[:3, :3])
    free = np.linalg.inv(fim)
    assert with_prior > 1.2 * np.sqrt(known[0, 0] + known[1, 1])
    assert with_prior < np.sqrt(free[0, 0] + free[1, 1]) / 1.2


def least_distance(layout, config):
    """The ambiguity by a double loop over every pair of grid points and every readout pair."""
    from ectskin.twin.bound import skin_grid

    best = np.inf
    for state in config.states_ml:
        prov = PointChargeResponse(layout, state)
        pts = []
        for skin in layout.skins:
            u_mm, v_mm = skin_grid(layout, skin.surface, config.spacing_mm)
            for v in v_mm:
                for u in u_mm:
                    c = prov.readout(skin.surface, [(u, v)], [1.0], [0.0])[0]
                    pts.append((skin.surface, np.array([u, v]), c, noise_pf(c, ReadoutConfig())))
        for (fa, xa, ca, sa), (fb, xb, cb, sb) in itertools.combinations(pts, 2):
            if fa == fb and np.hypot(*(xa - xb)) <= config.separation_mm:
                continue
            d2 = sum((ca[p] - cb[p]) ** 2 / ((sa[p] ** 2 + sb[p] ** 2) / 2) for p in range(len(ca)))
            best = min(best, np.sqrt(d2))
    return best


def test_the_ambiguity_is_the_least_noise_distance_between_distinct_points(analytic):
    layout, score = analytic
    assert score["ambiguity_sigma"] == pytest.approx(least_distance(layout, CONFIG), rel=1e-12)
    a = score["ambiguity"]
    assert min(a["per_state"]) == score["ambiguity_sigma"] and len(a["points"]) == 2
    # on a 4 mm grid the nearest neighbours (4 mm) are not distinct, the diagonal ones (5.7) are
    fine = replace(CONFIG, spacing_mm=4.0, states_ml=((0, 0, 0),))
    got = ambiguity(point_charges(layout, fine), layout, fine)
    assert got["sigma"] == pytest.approx(least_distance(layout, fine), rel=1e-12)
    (p, q) = (np.array(x["uv_mm"]) for x in got["points"])
    assert got["points"][0]["face"] != got["points"][1]["face"] or np.hypot(*(p - q)) > 5.0


def test_the_wire_length_is_the_sum_of_the_polylines(analytic):
    layout, score = analytic
    # straight routing, the wires 20 and 60 mm (front), 30 and 70 mm (back) from the pads
    assert score["wire_length_mm"] == pytest.approx(20.0 + 60.0 + 30.0 + 70.0)


# ---------------------------------------------------------------------------- files, bad input
class Counting:
    """``point_charges`` that counts the layouts it was asked for."""

    def __init__(self):
        self.calls = 0

    def __call__(self, layout, config):
        self.calls += 1
        return point_charges(layout, config)


def test_a_finished_score_is_read_back_and_other_settings_score_again(tmp_path):
    layout, count = two_wire_layout(), Counting()
    first = information_layout(layout, tmp_path, CONFIG, providers=count)
    assert count.calls == 1 and (tmp_path / INFORMATION_FILE).is_file()
    assert json.loads((tmp_path / INFORMATION_FILE).read_text())["bound_mm_p95"] == first[
        "bound_mm_p95"]
    again = information_layout(layout, tmp_path, CONFIG, providers=count)
    assert count.calls == 1 and again == first
    other = replace(CONFIG, spacing_mm=20.0)
    assert finished_information(tmp_path, layout, other) is None
    information_layout(layout, tmp_path, other, providers=count)
    assert count.calls == 2


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(states_ml=()), "states_ml must be one or more states"),
        (dict(states_ml=((0.0, -1.0, 0.0),)), "states_ml must be one or more states"),
        (dict(states_ml=((0, 0, 0), (0, 0, 0))), "states_ml repeats a state"),
        (dict(spacing_mm=0.0), "spacing_mm must be a finite number > 0, got 0.0"),
        (dict(force_n=float("nan")), "force_n must be a finite number > 0"),
        (dict(separation_mm=-1.0), "separation_mm must be a finite number >= 0"),
        (dict(mesh="fine"), "'mesh'"),
        (dict(nuisances=("wind",)), "'nuisance'"),
    ],
)
def test_bad_settings_are_one_clear_error(kwargs, message):
    with pytest.raises(EctskinError, match=message.replace("(", r"\(").replace(")", r"\)")):
        InformationConfig(**kwargs)


def test_a_state_with_the_wrong_number_of_chambers_is_refused_by_the_twin():
    with pytest.raises(EctskinError, match="inflation"):
        information_score(two_wire_layout(), InformationConfig(states_ml=((0.0, 0.0),)))


# ---------------------------------------------------------------------------- the twin, Dask
#: the twin's readouts on a 40 mm grid (3 points a face) at one state, every nuisance: seconds
TINY = InformationConfig(spacing_mm=40.0, states_ml=((10.0, 10.0, 10.0),))


def test_the_pulp_modulus_as_a_nuisance_never_lowers_the_bound():
    # the Fisher argument: one more estimated parameter (with its prior) can only widen the bound
    from dataclasses import replace

    from ectskin.layout import default_layout
    from ectskin.twin.bound import DEFAULT_PRIOR_SD

    lay = default_layout()
    without = information_score(lay, TINY)
    mod = replace(TINY, nuisances=(*TINY.nuisances, "modulus"),
                  prior_sd={**TINY.prior_sd, "modulus": DEFAULT_PRIOR_SD["modulus"]})
    with_mod = information_score(lay, mod)
    assert with_mod["maps"]["cases"][-2:] == ["all", "fit"] and "modulus" in with_mod["maps"]["cases"]
    worse = False
    for a, b in zip(without["maps"]["states"], with_mod["maps"]["states"]):
        for face in a["faces"]:
            for key in ("force_n", "position_mm"):
                pa = np.asarray(a["faces"][face]["contact"]["all"][key], dtype=float)
                pb = np.asarray(b["faces"][face]["contact"]["all"][key], dtype=float)
                assert np.all(pb >= pa * (1 - 1e-9)), (face, key)
                worse |= bool(np.any(pb > pa * 1.01))
    assert worse  # and it costs something somewhere


def test_the_score_is_identical_across_runs_and_worker_counts(tmp_path):
    """The paper's layout and one proposal, scored by the bound search serially, twice, and on
    two Dask workers: every number of design.json and information.json the same."""
    from ectskin.design.search import run_search

    runs = {}
    for name, workers in (("serial", 0), ("again", 0), ("dask", 2)):
        runs[name] = run_search(
            tmp_path / name, n_trials=1, information=TINY, n_workers=workers, seed=3
        )
    assert runs["dask"]["engine"]["n_workers"] == 2 and runs["serial"]["engine"]["n_workers"] == 1

    def numbers(design, folder):
        entries = [
            {k: v for k, v in e.items() if not k.startswith("information_")}
            for e in design["layouts"]
        ]
        maps = [
            json.loads((folder / e["folder"] / INFORMATION_FILE).read_text())["maps"]["states"]
            for e in design["layouts"]
        ]
        return entries, maps

    ref = numbers(runs["serial"], tmp_path / "serial")
    assert [e["name"] for e in ref[0]] == ["paper", "design-0000"]
    # each layout's cost: wall and this process's CPU time
    assert all(e["information_cpu_seconds"] > 0 for e in runs["serial"]["layouts"])
    assert all(e["bound_mm_p95"] > 0 for e in ref[0])
    for name in ("again", "dask"):
        got = numbers(runs[name], tmp_path / name)
        assert got == ref, (name, _first_difference(got, ref))
    # the search's value for the proposal is its score
    direct = information_score(_layout_of(tmp_path / "serial" / "layouts" / "design-0000"), TINY)
    assert direct["bound_mm_p95"] == ref[0][1]["bound_mm_p95"]
    assert direct["ambiguity_sigma"] == ref[0][1]["ambiguity_sigma"]


def _first_difference(a, b, path=""):
    """Where two JSON-like values first differ (for the assertion message)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{path}/{k}")
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            if x != y:
                return _first_difference(x, y, f"{path}[{i}]")
    return path, a, b


def _layout_of(folder):
    from ectskin.layout import load_layout

    return load_layout(folder / "layout.json")


def test_the_bound_search_minimises_the_worst_bound_the_electrodes_and_the_wire(tmp_path):
    """The default objective on the point-charge model: each trial's values are its score's
    (p95 bound, electrodes, wire length); the front, the figure and the report follow."""
    from functools import partial

    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    from ectskin.design.report import BOUND_FRONT_KEYS, pareto_front
    from ectskin.design.search import STUDY_FILE, STUDY_NAME, run_search

    score_fn = partial(information_layout, providers=point_charges)
    design = run_search(tmp_path, n_trials=4, information=CONFIG, n_workers=0, score_fn=score_fn)
    assert design["objective"] == "bound" and design["search"]["minimised"] == list(
        BOUND_FRONT_KEYS)
    entries = {e["name"]: e for e in design["layouts"]}
    assert set(entries) >= {"paper", "design-0000"}
    for e in entries.values():
        assert {"bound_mm_mean", "bound_mm_p95", "force_observable_share", "ambiguity_sigma",
                "wire_length_mm"} <= set(e) and "maps" not in e
    study = optuna.load_study(
        study_name=STUDY_NAME, storage=JournalStorage(JournalFileBackend(str(tmp_path / STUDY_FILE)))
    )
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(done) == design["search"]["n_complete"] >= 1
    for t in done:
        e = entries[f"design-{t.number:04d}"]
        assert t.values == [e["bound_mm_p95"], e["n_electrodes"], e["wire_length_mm"]]
    points = [e for n, e in entries.items() if n != "paper"]
    assert design["search"]["front"] == [p["name"] for p in pareto_front(points, BOUND_FRONT_KEYS)]
    paper = entries["paper"]
    half = [p["name"] for p in points
            if p["n_electrodes"] <= 8 and p["bound_mm_p95"] <= 0.5 * paper["bound_mm_p95"]]
    assert design["search"]["half_paper_worst_bound_with_le_8_electrodes"] == half
    assert (tmp_path / "figures" / "front.png").is_file()
    assert (tmp_path / "figures" / "paper_bound.png").is_file()
    md = (tmp_path / "design.md").read_text()
    assert "worst-case (p95) position bound (mm)" in md and "Information score:" in md
    assert "mean localisation error" not in md  # no trained score in this study


@pytest.mark.parametrize("objective, key", [("fit", "fit_error_mm_p95"),
                                            ("fit-median", "fit_error_mm_median")])
def test_the_fit_search_minimises_the_fit_error_not_the_bound(tmp_path, objective, key):
    """``--objective fit`` (``fit-median``) on the point-charge model: each trial's values are its
    score's (p95 (median) fit error, electrodes, wire length), its front is on that error;
    without a fit in the settings it is refused."""
    from functools import partial

    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    from ectskin.design.report import pareto_front
    from ectskin.design.search import STUDY_FILE, STUDY_NAME, run_search

    keys = (key, "n_electrodes", "wire_length_mm")
    score_fn = partial(information_layout, providers=point_charges)
    design = run_search(tmp_path, n_trials=4, information=CONFIG, n_workers=0, score_fn=score_fn,
                        objective=objective)
    assert design["objective"] == objective and design["search"]["minimised"] == list(keys)
    entries = {e["name"]: e for e in design["layouts"]}
    study = optuna.load_study(
        study_name=STUDY_NAME, storage=JournalStorage(JournalFileBackend(str(tmp_path / STUDY_FILE)))
    )
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(done) >= 1
    for t in done:
        e = entries[f"design-{t.number:04d}"]
        assert t.values == [e[key], e["n_electrodes"], e["wire_length_mm"]]
        assert e[key] != e["bound_mm_p95"]
        assert e["fit_error_mm_median"] != e["fit_error_mm_p95"]  # the two objectives differ
    points = [e for n, e in entries.items() if n != "paper"]
    assert design["search"]["front"] == [p["name"] for p in pareto_front(points, keys)]
    assert (tmp_path / "figures" / "front.png").is_file()
    with pytest.raises(EctskinError, match="no fit"):
        run_search(tmp_path / "nofit", n_trials=1, information=replace(CONFIG, fit=None),
                   n_workers=0, score_fn=score_fn, objective=objective)


def test_an_unresolved_worst_case_ranks_as_infinite_not_dropped(tmp_path):
    """Proposals whose worst case is unresolved (null in their files) are told to the study as
    inf and still make the front, by electrodes and wire length."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    from ectskin.design.report import BOUND_FRONT_KEYS, pareto_front
    from ectskin.design.search import STUDY_FILE, STUDY_NAME, run_search

    def score_fn(layout, out_dir, config):
        s = information_layout(layout, out_dir, config, providers=point_charges)
        return {**s, "bound_mm_p95": None} if layout.name != "paper-2x4-wires" else s

    design = run_search(tmp_path, n_trials=3, information=CONFIG, n_workers=0, score_fn=score_fn)
    study = optuna.load_study(
        study_name=STUDY_NAME, storage=JournalStorage(JournalFileBackend(str(tmp_path / STUDY_FILE)))
    )
    assert [t.values[0] for t in study.trials] == [float("inf")] * 3
    e = [{**x, "bound_mm_p95": float("inf")} for x in design["layouts"] if x["name"] != "paper"]
    want = [p["name"] for p in pareto_front(e, BOUND_FRONT_KEYS)]
    assert want and design["search"]["front"] == want
    assert (tmp_path / "figures" / "front.png").is_file()


def test_the_worst_case_is_inf_when_its_percentile_reaches_an_unresolved_point():
    from ectskin.design.information import worst_case

    x = np.arange(1.0, 21.0)  # 20 points: the 95th percentile sits at rank 18.05 (0-based)
    assert worst_case(x) == pytest.approx(np.percentile(x, 95))  # 19.05
    x[-1] = np.inf  # rank 18.05 interpolates between 19 and the unresolved point: inf
    assert worst_case(x) == np.inf
    x = np.r_[np.arange(1.0, 40.0), np.inf]  # 40 points: rank 37.05 lies among finite ones
    assert worst_case(x) == pytest.approx(38.05)
    assert worst_case(np.full(3, np.inf)) == np.inf
