"""Coordinated take-off plan (offboard/agent/takeoff.py, docs/lifecycle.md) and ground-start
pads."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from conftest import CUBE8, ROOT

from gcs.report.metrics import min_distance_by_phase
from offboard.agent.factory import make_agent
from offboard.agent.landing import LandingReference, landing_plan
from offboard.agent.leader import LeaderAgent
from offboard.agent.takeoff import (
    climb_xi,
    follower_xi,
    is_ground_start,
    leader_origin,
    min_column_separation,
    takeoff_plan,
)
from offboard.daemon.commands import GroundCommands
from swarm_common import wire
from swarm_common.scenario.model import ScenarioError, load_scenario

GROUND8 = ROOT / "scenarios" / "ground8.toml"


def test_cube8_defaults_to_airborne() -> None:
    sc = load_scenario(CUBE8)
    assert sc.lifecycle.start == "airborne" and not is_ground_start(sc)
    assert np.array_equal(leader_origin(sc, 0), sc.agents[0].position)


def test_plan_is_deterministic_and_layered() -> None:
    sc = load_scenario(GROUND8)
    a, b = takeoff_plan(sc), takeoff_plan(load_scenario(GROUND8))
    assert np.array_equal(a.pads, b.pads) and np.array_equal(a.z_stage, b.z_stage)
    assert (a.t_climb, a.t_blend, a.t_traj) == (b.t_climb, b.t_blend, b.t_traj)
    # staging altitudes = the cube's layers (leaders at 6 m, scale 4 m, lowest layer 2 m)
    layer = sc.vertices()[:, 2]
    assert np.allclose(a.z_stage, 2.0 + 4.0 * layer)
    assert min_column_separation(a) >= 2.0 * sc.controller.d_safe_m
    # the leaders' trajectory starts at their staging point, after the take-off window
    assert np.allclose(leader_origin(sc, 0), [4.0, 0.0, 6.0])
    assert a.t_traj >= a.t_blend > a.t_climb


def test_climb_reference_is_vertical_and_ends_at_rest() -> None:
    sc = load_scenario(GROUND8)
    plan = takeoff_plan(sc)
    for i in range(sc.n):
        xs = np.array([climb_xi(plan, i, t) for t in np.arange(0.0, plan.t_climb + 1.0, 0.05)])
        assert np.allclose(xs[:, 0:2], plan.pads[i, :2])  # its own column, all the way up
        assert np.all(np.diff(xs[:, 2]) >= -1e-12)
        assert xs[:, 5].max() <= sc.lifecycle.climb_rate_mps + 1e-9
        end = climb_xi(plan, i, plan.t_climb)
        assert end[2] == pytest.approx(plan.z_stage[i]) and np.allclose(end[3:], 0.0)


def test_follower_blend_is_continuous() -> None:
    sc = load_scenario(GROUND8)
    plan = takeoff_plan(sc)
    target = np.concatenate([[0.0, 0.0, 6.0], np.zeros(9)])
    before = follower_xi(plan, 2, plan.t_climb - 1e-6, target)
    after = follower_xi(plan, 2, plan.t_climb + 1e-6, target)
    assert np.allclose(before[:6], after[:6], atol=1e-4)
    assert np.allclose(follower_xi(plan, 2, plan.t_blend - 1e-6, target)[:3], target[:3],
                       atol=1e-4)
    assert np.array_equal(follower_xi(plan, 2, plan.t_blend, target), target)


def test_leader_climbs_then_holds_until_trajectory() -> None:
    sc = load_scenario(GROUND8)
    plan = takeoff_plan(sc)
    ld = LeaderAgent(sc, 1)
    assert np.allclose(ld.reference(0.0)[:3], [4.0, 0.0, 0.0])
    assert np.allclose(ld.reference(plan.t_traj - 0.01)[:3], [4.0, 0.0, 6.0])
    assert np.allclose(ld.reference(plan.t_traj + 1.0), ld.traj.state(plan.t_traj + 1.0))


def _variant(tmp_path: Path, old: str, new: str) -> Path:
    text = GROUND8.read_text()
    assert old in text
    p = tmp_path / "bad.toml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize(("old", "new", "expect"), [
    ("position = [1.0, 1.0, 0.0]", "position = [1.0, 1.0, 0.5]", ["agent[3].position", "z"]),
    ("position = [1.0, 1.0, 0.0]", "position = [0.6, 0.6, 0.0]",
     ["agent[3].position", "2 * controller.d_safe_m"]),
    ('start = "ground"', 'start = "sky"', ["lifecycle.start", "'ground'"]),
    ("climb_rate_mps = 1.0", "climb_rate_mps = 0.0", ["lifecycle.climb_rate_mps"]),
])
def test_bad_pads_refused_naming_the_key(
    tmp_path: Path, old: str, new: str, expect: list[str]
) -> None:
    with pytest.raises(ScenarioError) as ei:
        load_scenario(_variant(tmp_path, old, new))
    msg = str(ei.value)
    assert "\n" not in msg
    for s in expect:
        assert s in msg, (s, msg)


def test_phase_split() -> None:
    t = np.arange(0.0, 60.0, 0.5)
    md = np.full(len(t), 5.0)
    md[t == 1.0], md[t == 15.0], md[t == 30.0], md[t == 50.0] = 1.0, 2.0, 3.0, 4.0
    r = min_distance_by_phase(t, md, 20.0, takeoff_end_s=10.0, land_at_s=40.0)
    assert r == {"takeoff": 1.0, "formation": 2.0, "mission": 3.0, "landing": 4.0}
    r0 = min_distance_by_phase(t, md, 20.0)
    assert r0["takeoff"] is None and r0["landing"] is None and r0["formation"] == 1.0
    assert r0["mission"] == 3.0


def test_no_downward_command_on_the_pad_during_the_climb() -> None:
    sc = load_scenario(GROUND8)
    ld = LeaderAgent(sc, 1)
    u = np.array([0.5, -0.5, -3.0])
    assert np.array_equal(ld.on_pad_floor(0.5, 0.0, u), [0.5, -0.5, 0.0])
    assert np.array_equal(ld.on_pad_floor(0.5, 1.0, u), u)  # airborne: unchanged
    assert np.array_equal(ld.on_pad_floor(takeoff_plan(sc).t_climb, 0.0, u), u)
    assert np.array_equal(LeaderAgent(load_scenario(CUBE8), 1).on_pad_floor(0.5, 0.0, u), u)


def test_plan_start_time_shifts_every_time() -> None:
    sc = load_scenario(GROUND8)
    a, b = takeoff_plan(sc), takeoff_plan(sc, 12.3)
    assert a.t0 == 0.0 and b.t0 == 12.3
    assert b.t_climb == pytest.approx(a.t_climb + 12.3)
    assert b.t_blend == pytest.approx(a.t_blend + 12.3)
    # the leaders start their trajectory at a whole period: 5 s for ground8
    assert b.t_traj >= b.t_blend and b.t_traj % 5.0 == pytest.approx(0.0, abs=1e-9)
    for i in range(sc.n):
        assert np.allclose(climb_xi(b, i, 5.0), climb_xi(a, i, 0.0))  # on the pad until t0
        for s in (0.4, 2.0, 6.5):
            assert np.allclose(climb_xi(b, i, 12.3 + s), climb_xi(a, i, s))
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="take-off start time"):
            takeoff_plan(sc, bad)


def test_held_agents_idle_on_the_pad_until_start_takeoff() -> None:
    sc = load_scenario(GROUND8)
    leader, follower = make_agent(sc, sc.ids[0]), make_agent(sc, 4)
    assert isinstance(leader, LeaderAgent) and not isinstance(follower, LeaderAgent)
    assert leader.takeoff is not None
    pad = leader.takeoff.pads[leader.index]
    for ag in (leader, follower):
        assert ag.hold_for_takeoff() and ag.takeoff_held
    # idle (the control box's lowest vertical acceleration, no tilt) while held, any time
    u = np.array([0.5, -0.2, 3.0])
    assert np.array_equal(leader.on_pad_floor(30.0, 0.0, u), [0.0, 0.0, leader.u_lo[2]])
    assert np.allclose(leader.current_reference(30.0)[0:3], pad)
    assert np.allclose(leader.current_reference(30.0)[3:], 0.0)
    for ag in (leader, follower):
        assert ag.start_takeoff(20.0) and not ag.takeoff_held
        assert not ag.start_takeoff(25.0)  # once
        assert ag.takeoff is not None and ag.takeoff.t0 == 20.0
    # the leader climbs from t0 = 20 s as the plan of t0 = 0 did from 0
    ref0 = takeoff_plan(sc)
    assert np.allclose(leader.current_reference(22.0), climb_xi(ref0, leader.index, 2.0))
    assert leader.on_pad_floor(30.0, 5.0, u) is u
    airborne = make_agent(load_scenario(CUBE8), 1)
    assert not airborne.hold_for_takeoff() and not airborne.start_takeoff(1.0)


def _daemon() -> GroundCommands:
    """An offboard daemon's command handling alone (no links): a held ground8 leader."""
    sc = load_scenario(GROUND8)
    agent = make_agent(sc, 1)
    agent.hold_for_takeoff()
    return GroundCommands(sc, agent, 1)


@pytest.mark.parametrize("at_s", [float("nan"), float("inf"), 500.0])
def test_daemon_drops_a_bad_takeoff_time(at_s: float) -> None:
    d = _daemon()
    d.apply([wire.Command(kind="takeoff", at_s=at_s)], 10.0)  # 500: 490 s ahead
    assert d.bad_commands == 1 and d.agent.takeoff_held


def test_late_takeoff_climbs_from_now_without_a_jump(caplog: pytest.LogCaptureFixture) -> None:
    """A daemon whose loop stalled gets the command 7 s after its at_s: it climbs the same
    plan from its step time, not from 7 s into the plan (its reference would jump up)."""
    d = _daemon()
    pad = d.agent.current_reference(10.0)[0:3].copy()
    with caplog.at_level(logging.WARNING):
        d.apply([wire.Command(kind="takeoff", at_s=3.0)], 10.0)
    assert d.bad_commands == 0 and not d.agent.takeoff_held
    assert d.agent.takeoff is not None and d.agent.takeoff.t0 == 10.0
    assert "arrived late" in caplog.text
    assert np.allclose(d.agent.current_reference(10.0)[0:3], pad)  # still on the pad, at rest
    assert np.allclose(d.agent.current_reference(10.0)[3:], 0.0)
    # a late copy of it changes nothing; 0.9 s late joins the common plan
    d.apply([wire.Command(kind="takeoff", at_s=3.0)], 11.0)
    assert d.agent.takeoff.t0 == 10.0 and d.bad_commands == 0
    d = _daemon()
    d.apply([wire.Command(kind="takeoff", at_s=9.1)], 10.0)
    assert d.agent.takeoff is not None and d.agent.takeoff.t0 == 9.1


def test_daemon_takeoff_and_land_commands() -> None:
    d = _daemon()
    d.apply([wire.Command(kind="land", at_s=12.0), wire.Command(kind="takeoff", at_s=10.5)], 10.0)
    assert d.land_at is None  # on the pad: the land-all is ignored
    assert not d.agent.takeoff_held and d.agent.takeoff is not None
    assert d.agent.takeoff.t0 == 10.5 and d.bad_commands == 0
    # a second take-off changes nothing; land now
    d.apply([wire.Command(kind="takeoff", at_s=-1.0), wire.Command(kind="land", at_s=-1.0)], 30.0)
    assert d.agent.takeoff.t0 == 10.5 and d.land_at == 30.0
    d = _daemon()
    d.agent.start_takeoff(0.0)
    d.apply([wire.Command(kind="land", at_s=float("nan"))], 30.0)
    assert d.bad_commands == 1 and d.land_at is None


def test_late_land_all_keeps_the_common_pad_and_flies_it_from_now(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A daemon whose loop stalled across the land-all time t_L = 20 s reaches it 4 s
    late: it lands on the common plan's pad, timed from its step (its reference does not
    jump 4 s into the plan); 0.5 s late it flies the common plan itself."""
    sc = load_scenario(GROUND8)
    common = landing_plan(sc, 20.0)
    for late, t_land in ((4.0, 24.0), (0.5, 20.0)):
        d = _daemon()
        d.agent.start_takeoff(0.0)
        d.land_at = 20.0
        held = d.agent.current_reference(20.0 + late).copy()
        with caplog.at_level(logging.WARNING):
            d.maybe_start_landing(20.0 + late)
        landing = d.agent.landing
        assert landing is not None and landing.plan.t_land == t_land
        assert np.array_equal(landing.plan.pads, common.pads)
        assert np.array_equal(landing.plan.descent_delay, common.descent_delay)
        ref = d.agent.current_reference(20.0 + late)
        if late > 1.0:
            assert np.allclose(ref[0:6], held[0:6]) and "started late" in caplog.text
        else:  # the common plan, 0.5 s in: not where a plan timed from now would be
            assert np.array_equal(ref, LandingReference(
                common, d.agent.index, d.agent.reference(20.0)).xi(20.5))


def test_unknown_command_kind_fails_decode() -> None:
    raw = wire.encode(wire.Command(kind="takeoff", at_s=4.0))
    assert wire.decode(raw) == wire.Command(kind="takeoff", at_s=4.0)
    with pytest.raises(wire.WireError, match="unknown command kind"):
        wire.decode(wire.encode(wire.Command(kind="selfdestruct")))
