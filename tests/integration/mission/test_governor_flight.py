"""An infeasible leader trajectory (0.4 Hz, loaded with allow_infeasible) is slowed by the
reference governor and the swarm stays bounded and safe (docs/saturation.md), in process."""

import math

import numpy as np
import pytest
from conftest import ROOT  # noqa: E402

from gcs.mission.inproc import run_inproc
from offboard.agent.factory import make_agent
from offboard.agent.governor import governor_for
from swarm_common.scenario.model import load_scenario, with_overrides

CUBE8 = ROOT / "scenarios" / "cube8.toml"


@pytest.fixture(scope="module")
def fast():
    return with_overrides(
        load_scenario(CUBE8, allow_infeasible=True), leader_trajectory={"frequency_hz": 0.4}
    )


@pytest.fixture(scope="module")
def run10(fast):
    return run_inproc(fast, "dcbf", duration=10.0)


def test_every_agent_uses_the_same_governed_frequency(fast):
    gov = governor_for(fast)
    assert gov.slowed
    for a in fast.agents:
        assert make_agent(fast, a.id, "dcbf").governor == gov


def test_leaders_fly_the_slowed_trajectory(fast, run10):
    gov = governor_for(fast)
    s = run10.series
    lead = [fast.index_of(i) for i in fast.leader_ids]
    amp = np.array(fast.leader_trajectory.amplitude_m)
    t = s.t[:, None]
    for k in lead:
        p0 = fast.agents[k].position
        slowed = p0 + amp * (1.0 - np.cos(gov.omega * t))
        nominal = p0 + amp * (1.0 - np.cos(2.0 * math.pi * 0.4 * t))
        err_slowed = np.linalg.norm(s.p[:, k] - slowed, axis=1)
        err_nominal = np.linalg.norm(s.p[:, k] - nominal, axis=1)
        assert err_slowed.max() < 0.15
        assert err_nominal.max() > 0.5


def test_followers_stay_bounded_and_safe(fast, run10):
    m = run10.metrics
    assert m["collisions"] == 0
    assert m["min_distance_m"] >= fast.controller.d_safe_m
    s = run10.series
    fol = [fast.index_of(i) for i in fast.follower_ids]
    err = np.linalg.norm(s.p[:, fol] - s.p_des[:, fol], axis=2).max(axis=1)
    late = err[s.t >= 7.0]
    assert late.max() < 0.2
