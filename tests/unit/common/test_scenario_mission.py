"""A scenario's [mission] (swarm_common.scenario.mission_check): loaded, planned from the
scenario's formation, and refused at load time with one line naming the key."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import load_shipped

from swarm_common.scenario.feasibility import desired_origins
from swarm_common.scenario.files import ScenarioError
from swarm_common.scenario.mission_check import plan_for
from swarm_common.scenario.model import dump_toml, parse_scenario

ROOT = Path(__file__).resolve().parents[3]
CUBE8 = ROOT / "scenarios" / "cube8.toml"
MISSIONS = sorted((ROOT / "scenarios").glob("*.toml"))


def cube8_with(mission: dict, keep_sinusoid: bool = False) -> dict:
    data = tomllib.loads(CUBE8.read_text())
    if not keep_sinusoid:
        del data["leader_trajectory"]
    data["mission"] = mission
    return data


# 3 m/s at most, as the shipped missions: the default 5 m/s needs a longer sensing range
# than cube8's (swarm_common.scenario.safety_check)
GOOD = {"speed_mps": 1.5, "max_speed_mps": 3.0,
        "waypoint": [{"centroid": [2.0, 2.0, 4.0], "hold_s": 2.0},
                     {"centroid": [12.0, 2.0, 4.0], "yaw_deg": 90.0}]}


def test_a_mission_replaces_the_sinusoid_and_round_trips():
    sc = parse_scenario(cube8_with(GOOD))
    assert sc.mission is not None and sc.leader_trajectory.frequency_hz == 0.0
    again = parse_scenario(sc.to_toml_dict())
    assert again.mission == sc.mission
    plan = plan_for(sc)
    # the plan moves the scenario's own formation: at t = 0 every agent is at its p*(0)
    np.testing.assert_allclose(plan.all_xi(0.0)[:, :3], desired_origins(sc), atol=1e-12)
    np.testing.assert_allclose(plan.centroid_at(plan.arrival_s[-1]), [12.0, 2.0, 4.0],
                               atol=1e-12)


@pytest.mark.parametrize("path", MISSIONS, ids=lambda p: p.stem)
def test_every_shipped_scenario_loads(path):
    sc = load_shipped(path)
    if sc.mission is not None:
        plan = plan_for(sc)
        assert plan.end_s <= sc.run.duration_s, "the shipped mission ends within its run"


@pytest.mark.parametrize(("change", "names"), [
    (lambda d: d["mission"]["waypoint"].clear(), "mission.waypoint"),
    (lambda d: d["mission"]["waypoint"][1].update(scale=float("nan")), "waypoint[1].scale"),
    (lambda d: d["mission"]["waypoint"][1].update(centroid=[12.0, 2.0, 1.0]), "waypoint[1]"),
    (lambda d: d["mission"]["waypoint"][1].update(scale=0.05), "waypoint[1]"),
    (lambda d: d["mission"].update(speed_mps=40.0), "mission.speed_mps"),
    (lambda d: d["mission"].update(max_accel_mps2=6.0), "mission.max_accel_mps2"),
    (lambda d: d["mission"].update(waypoint=[{"centroid": [2.0, 2.0, 4.0]}] * 1001),
     "1001"),
    (lambda d: d["mission"].update(bogus=1), "bogus"),
])
def test_a_bad_mission_is_one_line_naming_the_key(change, names):
    data = cube8_with({**GOOD, "waypoint": [dict(w) for w in GOOD["waypoint"]]})
    change(data)
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data, "x.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("x.toml: ") and names in msg, msg


def test_a_mission_beside_a_moving_sinusoid_is_refused():
    with pytest.raises(ScenarioError, match=r"\[mission\] and \[leader_trajectory\]"):
        parse_scenario(cube8_with(GOOD, keep_sinusoid=True))


def test_a_yaw_needs_leaders_apart_horizontally():
    data = cube8_with(GOOD)
    # leaders 1 and 2 stacked: vertices (1, 0, 1) and (1, 0, 0), positions 4 m apart in z
    for a in data["agent"]:
        if a["id"] == 2:
            a["vertex"], a["position"] = [1, 0, 0], [4.0, 0.0, 2.0]
        elif a["id"] == 8:
            a["vertex"], a["position"] = [1, 1, 1], [4.0, 4.0, 6.0]
    with pytest.raises(ScenarioError, match="stacked vertically"):
        parse_scenario(data)


def test_a_mission_survives_the_toml_writer():
    """Distributed runs hand their children a written scenario (dump_toml): the mission's
    array of waypoint tables must come back as it was."""
    sc = parse_scenario(cube8_with(GOOD))
    back = parse_scenario(tomllib.loads(dump_toml(sc.to_toml_dict())))
    assert back.mission == sc.mission
