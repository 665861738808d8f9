"""The run's liveness warning (gcs.mission.preflight): a formation whose neighbours are
closer than the spacing at which dcbf lets two agents hover cannot form, and says so."""

from __future__ import annotations

import logging

import pytest
from conftest import ROOT

from gcs.mission.preflight import liveness_problem, smallest_spacing_m, warn_liveness
from swarm_common.scenario.model import load_scenario, with_overrides

SC = ROOT / "scenarios"
# cube8's filter: one margin for every jump, no trust region (docs/safety.md 5f)
CUBE8_FILTER = {"dcbf_trust_jump_mps2": 0.0, "dcbf_trust_error_mps2": 0.0,
                "dcbf_accel_error_mps2": 2.0, "dcbf_gamma_lin": 0.3}


def test_the_dense_cube_with_cube8s_filter_is_named(caplog: pytest.LogCaptureFixture) -> None:
    sc = with_overrides(load_scenario(SC / "dense_cube1p5.toml"), controller=CUBE8_FILTER)
    assert smallest_spacing_m(sc) == pytest.approx(1.5, abs=1e-6)
    line = liveness_problem(sc, "dcbf")
    assert line is not None and "1.50 m apart" in line and "2.75 m" in line
    assert "controller.dcbf_accel_error_mps2 = 2" in line
    assert liveness_problem(sc, "rcbf") is None  # the rest spacing is dcbf's
    with caplog.at_level(logging.WARNING):
        assert warn_liveness(sc, "dcbf")
    assert "cannot form" in caplog.text


@pytest.mark.parametrize("name", ["cube8", "dense_cube2", "dense_cube1p5", "gap8", "square27"])
def test_formations_that_form_are_not_named(name: str) -> None:
    assert liveness_problem(load_scenario(SC / f"{name}.toml"), "dcbf") is None


def test_a_mission_is_judged_at_its_smallest_scale() -> None:
    gap8 = load_scenario(SC / "gap8.toml")  # a 6 m cube flown down to scale 0.5
    assert smallest_spacing_m(gap8) == pytest.approx(3.0, abs=1e-6)
