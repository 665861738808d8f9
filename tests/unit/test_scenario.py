"""Scenario files: cube8 loads; bad keys, types and ranges give one line naming the key."""

from __future__ import annotations

import pytest
from conftest import CUBE8, ROOT
from scenario_variants import CASES, scenario_variant

from swarm_common.scenario import ScenarioError, load_scenario


def test_cube8_loads():
    sc = load_scenario(CUBE8)
    assert sc.name == "cube8" and sc.n == 8
    assert sc.ids == list(range(1, 9))
    assert sc.leader_ids == [1, 2]
    assert sc.substeps_per_control == 4
    assert sc.control_dt == pytest.approx(0.02)
    assert sc.vehicle.mass_kg == pytest.approx(1.8)
    assert sc.initial_positions()[0].tolist() == [4.0, 0.0, 6.0]
    assert sc.outages == ((5.0, 5.5), (15.0, 15.5), (40.0, 40.5))


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios").glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_scenario_loads(path):
    """Valid and feasible (swarm_common.feasibility): no --allow-infeasible needed."""
    sc = load_scenario(path)
    assert sc.n >= 2 and not sc.allow_infeasible


@pytest.mark.parametrize(("old", "new", "expect"), CASES)
def test_invalid_values_name_the_key(tmp_path, old, new, expect):
    p = scenario_variant(tmp_path, old, new)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert "\n" not in msg
    assert str(p) in msg
    for e in expect:
        assert e in msg, (e, msg)


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "nope.toml")
    p = tmp_path / "x.toml"
    p.write_text("[scenario\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(p)
