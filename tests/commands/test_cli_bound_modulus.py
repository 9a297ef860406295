"""`ectskin bound --nuisance ...,modulus`: the pulp's modulus as a nuisance of the direct bound,
its prior by default the twin's spread, its column the one `twin.bound_modulus` solves apart."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ectskin.cli import main
from ectskin.layout import default_layout
from ectskin.twin.bound import COARSE, TwinResponse, crb, finite_difference_jacobian
from ectskin.twin.bound_modulus import MODULUS_PRIOR_SD, modulus_column
from ectskin.twin.readout import ReadoutConfig, noise_pf
from ectskin.twin.sensor import SensorModel

# one state, one face, a 40-mm grid (1 x 3 cells): 3 points of 11 solves each
RUN = ["--states", "0,0,0", "--faces", "front", "--spacing-mm", "40", "--nuisance",
       "finger,modulus", "--workers", "0", "--no-progress"]


@pytest.fixture(scope="module")
def doc(tmp_path_factory):
    out = tmp_path_factory.mktemp("bound")
    assert main(["bound", str(out), *RUN]) == 0
    return json.loads((out / "bound.json").read_text())


def test_the_modulus_case_is_the_bound_of_its_direct_column(doc):
    assert doc["cases"] == ["none", "finger", "modulus", "all"]
    assert doc["settings"]["prior_sd"]["modulus"] == pytest.approx(MODULUS_PRIOR_SD, abs=1e-3)
    face = doc["states"][0]["faces"]["front"]
    u, v = face["u_mm"][0], face["v_mm"][1]
    sensor = SensorModel(default_layout(), discretisation=COARSE)
    c, J, _ = finite_difference_jacobian(TwinResponse(sensor, (0, 0, 0)), "front", (u, v))
    col = modulus_column(sensor, (0, 0, 0), "front", [(u, v)], 1.0)[0]
    prior = doc["settings"]["prior_sd"]["modulus"] ** 2
    ref = crb(np.c_[J, col], noise_pf(c, ReadoutConfig()), nuisance_cols=[3],
              prior_var={3: prior})
    contact = face["contact"]
    assert contact["modulus"]["force_n"][1][0] == pytest.approx(ref.std[2], rel=1e-6)
    assert contact["none"]["force_n"][1][0] == pytest.approx(
        crb(J, noise_pf(c, ReadoutConfig())).std[2], rel=1e-6)
    for case in ("modulus", "all"):  # a nuisance never lowers the bound
        assert np.all(np.array(contact[case]["force_n"]) >= np.array(contact["none"]["force_n"]))
    assert np.all(np.array(contact["all"]["force_n"]) >= np.array(contact["finger"]["force_n"]))
