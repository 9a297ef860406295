"""Seeds of the inversion's fit (:mod:`ectskin.inversion.seed`): guesses of the fingers that
join the coarse search's starts ("add") or stand in for them ("replace").

References: noise-free frames of the closed-form flat skin (``conftest``) at known points, where
the truth is the exact minimum (χ² = 0). On a coarse node table (9 mm apart) with one start per
count the coarse search puts a share of those frames in the wrong basin: a seed at the truth
must then give the truth back, and never a fit worse than the unseeded one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ectskin._check import EctskinError
from ectskin.inversion import FingerGuess, Inversion
from ectskin.inversion.model import NodeTable
from ectskin.inversion.seed import seed_starts

STATE = (0.0,)


def _points(n: int, seed: int = 0) -> list[tuple[float, float, float]]:
    rng = np.random.default_rng(seed)
    return [(float(rng.uniform(-17, 17)), float(rng.uniform(3, 57)), float(rng.uniform(0.4, 1.9)))
            for _ in range(n)]


def _error(r, u: float, v: float) -> float:
    e = next((f for f in r.fingers if f.contact), None)
    return math.inf if e is None or r.n_fingers != 1 else float(np.hypot(e.u_mm - u, e.v_mm - v))


def test_a_seed_at_the_truth_mends_a_wrong_coarse_search_and_never_does_worse(
        make_analytic_field):
    field = make_analytic_field(spacing_mm=9.0)
    inv = Inversion({STATE: field}, starts=1)
    missed = 0
    for u, v, f in _points(60):
        y = field.readout("front", u, v, f)
        plain = inv.fit(y, STATE)
        seeded = inv.fit(y, STATE, seeds=[[FingerGuess("front", u, v, force_n=f)]])
        missed += _error(plain, u, v) > 1.0
        # the truth is the exact minimum: the seeded fit finds it, whatever the search did
        assert seeded.n_fingers == 1 and seeded.fingers[0].contact
        e = seeded.fingers[0]
        np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n], [u, v, f], atol=1e-4)
        assert seeded.log_likelihood >= plain.log_likelihood - 1e-6
        assert seeded.bic <= plain.bic + 1e-6
    assert missed >= 5  # the coarse search is wrong on these frames (else this tests nothing)


def test_an_added_wrong_seed_leaves_the_fit_as_it_was(analytic_field):
    """Beside the coarse search a seed far from the finger cannot make the fit worse: the fit
    of the coarse search's start is kept where it is better."""
    inv = Inversion({STATE: analytic_field})
    for u, v, f in _points(8, seed=1):
        y = analytic_field.readout("front", u, v, f)
        r = inv.fit(y, STATE, seeds=[[FingerGuess("front", -u, 60.0 - v, force_n=1.9)]])
        e = r.fingers[0]
        np.testing.assert_allclose([e.u_mm, e.v_mm, e.force_n], [u, v, f], atol=1e-4)


def test_replace_skips_the_coarse_search_of_a_seeded_count(analytic_field, monkeypatch):
    """"replace": the count a seed gives a start is fitted from the seed alone (the node
    table's search is never asked); "add" asks it too."""
    calls = []
    real = NodeTable.starts

    def spy(self, *a, **k):
        calls.append(1)
        return real(self, *a, **k)

    monkeypatch.setattr(NodeTable, "starts", spy)
    u, v, f = 3.3, 21.7, 1.1
    y = analytic_field.readout("front", u, v, f)
    truth = [[FingerGuess("front", u, v, force_n=f)]]
    r = Inversion({STATE: analytic_field}, seed_search="replace").fit(y, STATE, seeds=truth)
    assert calls == [] and r.n_fingers == 1
    np.testing.assert_allclose([r.fingers[0].u_mm, r.fingers[0].v_mm], [u, v], atol=1e-4)
    Inversion({STATE: analytic_field}, seed_search="add").fit(y, STATE, seeds=truth)
    assert calls
    with pytest.raises(EctskinError, match="seed_search"):
        Inversion({STATE: analytic_field}, seed_search="instead")


def test_seed_starts_are_the_inversions_parameters(analytic_field):
    m = Inversion({STATE: analytic_field}).model(STATE)
    press, hover = FingerGuess("front", 1.0, 2.0, force_n=0.7), FingerGuess(
        "front", -3.0, 4.0, height_mm=3.0)
    out = seed_starts(m, [[press], [press, hover], [FingerGuess("back", 0, 0, force_n=1)]], 2)
    assert sorted(out) == [1, 2]  # the face the field lacks is left out
    (fi, mi, x), = out[1][0]
    assert (m.faces[fi], ("contact", "hover")[mi]) == ("front", "contact")
    np.testing.assert_allclose(x, [1.0, 2.0, 0.7])
    fi, mi, x = out[2][0][1]
    assert ("contact", "hover")[mi] == "hover"
    np.testing.assert_allclose(x, [-3.0, 4.0, math.log(3.0)])
    assert seed_starts(m, [[press, hover]], 1) == {}  # a count the inversion does not fit


@pytest.mark.parametrize("make, match", [
    (lambda: FingerGuess("front", 1.0, 2.0), "exactly one of force_n"),
    (lambda: FingerGuess("front", 1.0, 2.0, force_n=1.0, height_mm=2.0), "exactly one"),
    (lambda: FingerGuess("front", math.nan, 2.0, force_n=1.0), "u_mm must be a finite"),
    (lambda: FingerGuess("front", 1.0, 2.0, height_mm=-1.0), "height_mm must be"),
])
def test_a_bad_guess_is_refused_by_name(make, match):
    with pytest.raises(EctskinError, match=match):
        make()


def test_bad_seeds_are_refused_by_name(analytic_field):
    inv = Inversion({STATE: analytic_field})
    y = analytic_field.readout("front", 0.0, 30.0, 1.0)
    g = FingerGuess("front", 0.0, 30.0, force_n=1.0)
    with pytest.raises(EctskinError, match=r"seeds\[0\] must be a sequence of 1 to 2"):
        inv.fit(y, STATE, seeds=[[g, g, g]])
    with pytest.raises(EctskinError, match="seeds must be a sequence of seeds"):
        inv.fit(y, STATE, seeds=g)
