"""Ground start → take-off → formation → land-all (scenarios/ground8.toml, docs/lifecycle.md)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT

from gcs.mission.inproc import run_inproc
from offboard.agent.takeoff import takeoff_plan
from swarm_common.scenario.model import load_scenario

GROUND8 = ROOT / "scenarios" / "ground8.toml"


@pytest.mark.parametrize("method", ["rcbf", "dcbf"])
def test_ground8_takes_off_forms_and_lands(method: str) -> None:
    sc = load_scenario(GROUND8)
    res = run_inproc(sc, method=method, duration=60.0, land_at=40.0)
    m = res.metrics
    assert m["collisions"] == 0
    assert m["min_distance_m"] >= 0.5
    ph = m["min_distance_by_phase_m"]
    assert ph["takeoff"] is not None and ph["landing"] is not None
    assert min(ph.values()) == m["min_distance_m"]
    ser = res.series
    assert np.all(ser.p[0, :, 2] == 0.0)  # started on the pads
    # formed before the land-all: every follower within 0.1 m of its desired position
    k = int(round(39.0 / sc.control_dt))
    f = [i for i in range(sc.n) if not sc.agents[i].is_leader]
    assert np.linalg.norm(ser.p[k, f] - ser.p_des[k, f], axis=1).max() < 0.1
    assert ser.p[k, :, 2].min() > 0.5 * takeoff_plan(sc).z_stage.min()
    assert ser.p[-1, :, 2].max() < 0.1  # all landed
