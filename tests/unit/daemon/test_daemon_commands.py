"""The offboard daemon's ground-station commands (offboard.daemon.commands: one handler
per CommandKind) and its drivers' setpoint freshness rules (offboard.daemon.drivers)."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import SupportsFloat

import numpy as np
import pytest
from conftest import CUBE8

from offboard.agent.factory import make_agent
from offboard.daemon.commands import GroundCommands
from offboard.daemon.drivers import LockstepDriver, RealtimeDriver
from offboard.daemon.mavlink.odometry import Odometry
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.runner_loss import RunnerLoss
from offboard.daemon.stream import SetpointStream
from swarm_common import wire
from swarm_common.enums import CommandKind, Method
from swarm_common.scenario.model import load_scenario


def _commands(agent_id: int = 2) -> GroundCommands:
    sc = load_scenario(CUBE8)
    return GroundCommands(sc, make_agent(sc, agent_id), agent_id)


def test_every_kind_on_the_wire_has_a_handler() -> None:
    assert wire.COMMAND_KINDS == ("method", "outage", "land", "takeoff", "mission", "hold",
                                  "live")
    assert [k.value for k in CommandKind] == list(wire.COMMAND_KINDS)
    assert set(_commands().handlers) == set(CommandKind)
    for kind in CommandKind:  # a StrEnum member is its word on the wire
        raw = wire.encode(wire.Command(kind=kind, at_s=1.0))
        assert raw == wire.encode(wire.Command(kind=kind.value, at_s=1.0))
        assert wire.key_cmd("cube8", kind) == f"swarm/cube8/cmd/{kind.value}"


def test_unknown_kind_is_counted_and_logged_not_a_crash(caplog: pytest.LogCaptureFixture) -> None:
    c = _commands()
    with caplog.at_level(logging.WARNING):
        c.apply([wire.Command(kind="selfdestruct"), wire.Command(kind="land", at_s=12.0)], 5.0)
    assert c.unknown_commands == 1 and c.bad_commands == 0
    assert "unknown kind 'selfdestruct'" in caplog.text
    assert c.land_at == 12.0  # the next command of the batch still applies


def test_outage_and_method_commands() -> None:
    c = _commands()
    assert c.comm_ok(3.0)
    c.apply([wire.Command(kind=CommandKind.OUTAGE, duration_s=0.0)], 3.0)  # none: ignored
    assert c.extra_outages == []
    c.apply([wire.Command(kind=CommandKind.OUTAGE, duration_s=1.5)], 3.0)
    assert c.extra_outages == [(3.0, 4.5)]
    assert not c.comm_ok(3.0) and not c.comm_ok(4.49) and c.comm_ok(4.5)
    follower = c.agent
    c.apply([wire.Command(kind=CommandKind.METHOD, method="no-such-method")], 4.0)
    c.apply([wire.Command(kind=CommandKind.METHOD, method="apf")], 4.0)
    assert follower.method is Method.APF
    assert c.bad_commands == 0 and c.unknown_commands == 0


def test_land_command_keeps_the_first_land_time() -> None:
    c = _commands()
    c.apply([wire.Command(kind=CommandKind.LAND, at_s=-1.0)], 7.0)
    c.apply([wire.Command(kind=CommandKind.LAND, at_s=20.0)], 8.0)
    assert c.land_at == 7.0


class _Vehicle:
    """The VehiclePort of a test: records the setpoints sent."""

    def __init__(self) -> None:
        self.odometry: Odometry | None = None
        self.armed = False
        self.in_offboard = False
        self.offboard_reported = False
        self.custom_mode = 0
        self.sent: list[int] = []

    def send_attitude_target(self, time_boot_ms: int, q_wxyz: Iterable[SupportsFloat],
                             thrust_norm: SupportsFloat) -> None:
        self.sent.append(time_boot_ms)


def _stream(driver: LockstepDriver | RealtimeDriver | None, vehicle: _Vehicle,
            loss: RunnerLoss) -> SetpointStream:
    assert driver is not None
    return SetpointStream(2, vehicle, OffboardKeeper(0.6, False), loss, driver.answer_fresh)


def test_lockstep_answer_is_fresh_for_its_own_step_only() -> None:
    vehicle, loss = _Vehicle(), RunnerLoss(50)
    driver = LockstepDriver(None, 2, [], {}, None, solo=True,  # type: ignore[arg-type]
                            startup_timeout=1.0, neighbour_timeout=0.45, stopped=lambda: False)
    s = _stream(driver, vehicle, loss)
    s.send()
    assert vehicle.sent == []  # no answer yet
    s.vehicle_step = 4
    s.set_answer((80, np.zeros(4, np.float32), np.float32(0.5)), 4, from_loss=False)
    s.send()
    s.answer_at -= 10.0  # however old: lockstep's clock waits for it
    s.send()
    assert vehicle.sent == [80, 80] and s.streaming
    s.vehicle_step = 5  # the vehicle moved on: the answer no longer goes out
    s.send()
    assert vehicle.sent == [80, 80] and not driver.fallback_step(5, 0.1, 100, s)


def test_realtime_answer_is_fresh_for_one_period() -> None:
    sc = load_scenario(CUBE8)
    vehicle, loss = _Vehicle(), RunnerLoss(50)
    driver = RealtimeDriver(sc, make_agent(sc, 2), 2, vehicle, None,  # type: ignore[arg-type]
                            {}, keeper=OffboardKeeper(0.6, False), modes=None,  # type: ignore[arg-type]
                            loss=loss, nav_gate_m=0.0, manual_start=False)
    s = _stream(driver, vehicle, loss)
    s.vehicle_step = 4
    s.set_answer((80, np.zeros(4, np.float32), np.float32(0.5)), 4, from_loss=False)
    s.vehicle_step = 6  # the vehicle's clock ran on: still fresh within a period
    s.send()
    assert vehicle.sent == [80]
    s.answer_at -= 0.03  # older than one period (20 ms)
    s.send()
    assert vehicle.sent == [80] and driver.summary() == ""
    assert not driver.fallback_step(6, 0.12, 120, s)  # the runner is not lost


def _mission_leader(agent_id: int = 1) -> GroundCommands:
    sc = load_scenario(CUBE8.replace("cube8.toml", "course8.toml"))
    return GroundCommands(sc, make_agent(sc, agent_id), agent_id)


def _goto(x: float, y: float, z: float, **extra: float) -> str:
    import json

    return json.dumps({"speed_mps": 1.5, "max_speed_mps": 3.0,
                       "waypoint": [{"centroid": [x, y, z], **extra}]})


def test_a_mission_command_replans_every_leader_alike_and_followers_ignore_it() -> None:
    a, b, f = _mission_leader(1), _mission_leader(2), _mission_leader(3)
    cmd = wire.roundtrip(wire.Command(kind="mission", at_s=5.0,
                                      mission=_goto(2.0, 2.0, 6.0, scale=1.2, yaw_deg=30.0)))
    assert isinstance(cmd, wire.Command)
    for c in (a, b, f):
        c.apply([cmd], 1.0)
        assert c.bad_commands == 0
    # course8 holds at its first waypoint until 10 s: the new plan starts at 5 s from there
    t_end = 40.0
    xa, xb = a.agent.reference(t_end), b.agent.reference(t_end)
    la, lb = a.agent, b.agent
    assert isinstance(la, type(lb))
    offset = xb[:2] - xa[:2]  # leader 2 − leader 1: (0, 4) m at scale 1, yaw 0
    assert np.hypot(*offset) == pytest.approx(4.0 * 1.2, abs=1e-9)
    assert np.degrees(np.arctan2(offset[1], offset[0])) == pytest.approx(90.0 + 30.0, abs=1e-9)
    assert np.all(xa[3:] == 0.0)  # arrived and at rest


def test_bad_mission_commands_are_counted_and_change_nothing(
    caplog: pytest.LogCaptureFixture,
) -> None:
    c = _mission_leader(1)
    before = c.agent.reference(30.0).copy()
    bad = [
        wire.Command(kind="mission", at_s=5.0, mission="{not json"),
        wire.Command(kind="mission", at_s=5.0, mission=_goto(2.0, 2.0, 0.1)),  # under floor
        wire.Command(kind="mission", at_s=5.0, mission='{"speed_mps": 1.5}'),  # no waypoint
        wire.Command(kind="mission", at_s=float("nan"), mission=_goto(2.0, 2.0, 6.0)),
        wire.Command(kind="hold", at_s=1e9),
    ]
    with caplog.at_level(logging.WARNING):
        c.apply(bad, 1.0)
    assert c.bad_commands == len(bad)
    assert "waypoint[0]" in caplog.text
    np.testing.assert_array_equal(c.agent.reference(30.0), before)
    # a scenario without a mission flies its sinusoid: a mission command is refused
    s = _commands(1)
    s.apply([wire.Command(kind="mission", at_s=5.0, mission=_goto(4.0, 2.0, 4.0))], 1.0)
    assert s.bad_commands == 1


def test_hold_stops_at_the_next_rest() -> None:
    c = _mission_leader(1)
    plan_arrival = 27.85  # course8's second waypoint (docs/missions.md)
    c.apply([wire.Command(kind="hold", at_s=15.0)], 14.0)  # flying leg 1
    assert c.bad_commands == 0
    held = c.agent.reference(plan_arrival + 30.0)
    np.testing.assert_allclose(held[:3], c.agent.reference(plan_arrival)[:3], atol=1e-9)
    assert np.all(held[3:] == 0.0)


def test_a_live_command_moves_every_leader_alike_and_then_stops() -> None:
    """A live velocity (gcs.formation.live) read off the wire: both leaders fly it from its
    at_s, alike (their offset stays the shape's), and come to rest by themselves."""
    a, b, f = _mission_leader(1), _mission_leader(2), _mission_leader(3)
    cmd = wire.roundtrip(wire.Command(kind="live", at_s=5.0, velocity=(1.0, -0.5, 0.0)))
    assert isinstance(cmd, wire.Command) and cmd.velocity == (1.0, -0.5, 0.0)
    for c in (a, b, f):
        c.apply([cmd], 4.0)
        assert c.bad_commands == 0
    x0 = a.agent.reference(5.0)
    moving = a.agent.reference(6.0)  # the end of its 1 s: still flying
    assert moving[3] > 0.3 and moving[4] < -0.15  # east and south
    late = 30.0
    xa, xb = a.agent.reference(late), b.agent.reference(late)
    assert np.all(xa[3:] == 0.0)  # it braked to rest by itself
    assert xa[0] - x0[0] > 0.5 and xa[1] - x0[1] < -0.2
    np.testing.assert_allclose(xb[:3] - xa[:3], b.agent.reference(5.0)[:3] - x0[:3],
                               atol=1e-9)  # the shape is kept


def test_bad_live_commands_are_counted_and_change_nothing() -> None:
    c = _mission_leader(1)
    before = c.agent.reference(30.0).copy()
    bad = [
        wire.Command(kind="live", at_s=5.0, velocity=(float("nan"), 0.0, 0.0)),
        wire.Command(kind="live", at_s=5.0, velocity=(50.0, 0.0, 0.0)),  # too fast
        wire.Command(kind="live", at_s=5.0, velocity=(0.0, 0.0, -3.0)),  # into the floor
    ]
    c.apply(bad, 4.0)
    assert c.bad_commands == len(bad)
    np.testing.assert_array_equal(c.agent.reference(30.0), before)
    with pytest.raises(wire.WireError):  # a velocity of the wrong length never decodes
        raw = wire.encode(wire.Command(kind="live", at_s=5.0, velocity=(1.0, 0.0, 0.0)))
        wire.decode(raw.replace(np.asarray([1.0, 0.0, 0.0], "<f4").tobytes(), b"\0" * 8))
