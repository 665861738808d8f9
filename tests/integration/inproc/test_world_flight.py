"""cube8 with ten obstacles and a geofence flown in process (docs/world.md): the dcbf
filter keeps every obstacle and fence barrier ≥ 0, where no filter breaks them and the
verdict says so, naming the obstacles."""

from __future__ import annotations

from conftest import ROOT

from gcs.mission.inproc import run_inproc
from swarm_common.scenario.model import load_scenario

OBSTACLES = ROOT / "scenarios" / "cube8_obstacles.toml"


def test_obstacles_kept_by_dcbf_and_broken_without_a_filter() -> None:
    sc = load_scenario(OBSTACLES)
    m = run_inproc(sc, "dcbf", seed=2, duration=20.0).metrics
    assert m["obstacle_h_min_m"] >= 0.0 and m["fence_h_min_m"] >= 0.0
    assert m["obstacle_min_distance_m"] >= 0.5 and m["collisions"] == 0
    assert m["safety_verdict"] in ("safe", "alarm") and m["h_min"] >= 0.0
    assert not [e for e in m["safety_alarms"] if e["assumption"] in ("obstacle", "geofence")]
    none = run_inproc(sc, "none", seed=2, duration=20.0).metrics
    assert none["obstacle_h_min_m"] < 0.0 and none["safety_verdict"] == "unsafe"
    hits = [e for e in none["safety_alarms"] if e["assumption"] == "obstacle"]
    assert hits and all(0 <= e["other"] < len(sc.world.obstacles) for e in hits)
