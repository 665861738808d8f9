"""The run's liveness warning (gcs.mission.preflight): a formation whose neighbours are
closer than the spacing at which dcbf lets two agents hover cannot form, and says so."""

from __future__ import annotations

import logging

import pytest
from conftest import ROOT

from gcs.mission.preflight import (
    OBSERVER_RATE_MIN,
    liveness_problem,
    observer_problem,
    smallest_spacing_m,
    warn_liveness,
)
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


def test_a_slow_desired_state_observer_is_named(caplog: pytest.LogCaptureFixture) -> None:
    """The slowest channel is reference_gain · λ_min: cube8's 0.76 1/s passes, and halving
    its gain (0.38 1/s, under OBSERVER_RATE_MIN) is named, for every method."""
    cube8 = load_scenario(SC / "cube8.toml")
    assert observer_problem(cube8) is None
    slow = with_overrides(cube8, observer={"reference_gain": 2.0})
    line = observer_problem(slow)
    assert line is not None and "decays at 0.38 1/s" in line and "--leaders" in line
    assert 0.38 < OBSERVER_RATE_MIN
    with caplog.at_level(logging.WARNING):
        assert warn_liveness(slow, "rcbf")
        assert not warn_liveness(cube8, "rcbf")
    assert caplog.text.count("may not form") == 1


@pytest.mark.parametrize("path", sorted(SC.glob("*.toml")), ids=lambda p: p.stem)
def test_no_shipped_scenario_has_a_slow_observer(path) -> None:
    try:
        sc = load_scenario(path)
    except ValueError:  # the scenarios kept to show a refusal
        return
    assert observer_problem(sc) is None


def test_a_runs_document_lists_its_preflight_warnings(tmp_path) -> None:
    """The warnings a run starts with are in its metrics.json (``preflight``), in process
    and distributed alike (gcs.mission.score.score_run moves them out of the run facts)."""
    import json

    from gcs.mission.inproc import run_inproc
    from gcs.mission.recorder import Recorder
    from gcs.mission.score import score_run

    cube8 = load_scenario(SC / "cube8.toml")
    slow = with_overrides(cube8, observer={"reference_gain": 2.0})
    res = run_inproc(slow, "dcbf", duration=0.1)
    res.save(tmp_path)
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["preflight"] == [observer_problem(slow)]
    assert run_inproc(cube8, "dcbf", duration=0.1).document()["preflight"] == []
    facts = {"failed_agents": [], "preflight": ["a line"], "wall_s": 0.0}
    doc, _ = score_run(Recorder(slow, 5, seed=1), slow, facts, "dcbf", None, False, None, 0.1)
    assert doc["preflight"] == ["a line"] and "preflight" not in doc["run"]
