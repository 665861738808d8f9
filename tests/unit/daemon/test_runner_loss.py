"""offboard.daemon.runner_loss: loss detection, the land time, the commit, and the odometry
lander flying its slot of the landing plan down to idle (a point-mass model, no I/O)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from offboard.agent.landing import landing_plan
from offboard.daemon.runner_loss import (
    LEAD_S,
    RUNNER_LOST_PERIODS,
    STALLED_PERIODS,
    LossFlight,
    OdometryFlight,
    RunnerLoss,
    loss_landing_plan,
)
from swarm_common.scenario.model import load_scenario

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
HZ = 50


def test_lost_after_the_threshold_and_back_before_the_commit() -> None:
    loss = RunnerLoss(HZ, 3.0)
    assert loss.observe(100, None) is None and not loss.lost  # no truth yet: not a loss
    assert loss.observe(100 + STALLED_PERIODS, 100) is None and not loss.lost
    assert loss.observe(101 + STALLED_PERIODS, 100) == "stalled" and loss.lost
    assert loss.t_land is None and not loss.commit_due(1e6)  # a stall sets no land time
    assert loss.observe(100 + RUNNER_LOST_PERIODS, 100) is None and loss.episode == 1
    assert loss.observe(101 + RUNNER_LOST_PERIODS, 100) == "lost" and loss.lost
    assert loss.t_s == pytest.approx(2.0) and loss.t_land == pytest.approx(5.0)
    assert not loss.commit_due(5.0 - LEAD_S - 0.02)
    assert loss.observe(200, 199) == "back" and not loss.lost and loss.t_land is None


def test_after_the_commit_truth_coming_back_changes_nothing() -> None:
    loss = RunnerLoss(HZ, 3.0)
    loss.observe(200, 150)
    assert loss.commit_due(3.0 + 3.0 - LEAD_S)
    loss.commit()
    assert loss.landing and loss.observe(400, 400) is None and loss.lost


def test_zero_never_lands_and_bad_values_are_refused() -> None:
    loss = RunnerLoss(HZ, 0.0)
    loss.observe(200, 100)
    assert loss.lost and loss.t_land is None and not loss.commit_due(1e6)
    for bad in (1.0, -3.0, float("nan"), float("inf"), 4000.0):
        with pytest.raises(ValueError):
            RunnerLoss(HZ, bad)


def test_plan_pads_from_t_s_timing_from_t_land() -> None:
    sc = load_scenario(str(CUBE8))
    plan = loss_landing_plan(sc, 8.1, 11.1)
    ref = landing_plan(sc, 8.1)
    assert plan.t_land == 11.1 and np.array_equal(plan.pads, ref.pads)
    # a disagreement of two control periods moves no pad by more than 5 cm
    near = loss_landing_plan(sc, 8.1 + 2.0 / HZ, 11.1)
    assert float(np.max(np.linalg.norm(near.pads - plan.pads, axis=1))) < 0.05


def _fly(lander: OdometryFlight, p: np.ndarray, t0: float, t1: float, dt: float,
         v0: np.ndarray | None = None) -> tuple[np.ndarray, float | None]:
    """Point mass under the lander's u with a constant 0.3 m/s² push (ground at z = 0)."""
    v = np.zeros(3) if v0 is None else np.array(v0, dtype=float)
    landed_at = None
    t = t0
    while t < t1:
        _, u = lander.command(t, p, v)
        a = u + np.array([0.3, 0.0, 0.3])
        v = v + a * dt
        p = p + v * dt
        if p[2] <= 0.0:
            p[2], v = 0.0, np.zeros(3)
        if landed_at is None and lander.landed(t, float(p[2])):
            landed_at = t
        t += dt
    return p, landed_at


def test_lander_holds_then_lands_on_its_pad_and_idles() -> None:
    sc = load_scenario(str(CUBE8))
    index = sc.index_of(3)  # a top-layer follower: its pad is moved outward
    p_hold = np.array([2.0, 0.4, 5.1])
    lander = OdometryFlight.landing(sc, index, 8.1, 11.1, p_hold)
    p, _ = _fly(lander, p_hold.copy(), 10.1, 11.1, 0.02)  # before t_L: hold
    assert float(np.linalg.norm(p - p_hold)) < 0.15
    p, landed_at = _fly(lander, p, 11.1, 40.0, 0.02)
    assert landed_at is not None and landed_at >= lander.ref.t_end
    assert p[2] == 0.0 and float(np.linalg.norm(p[:2] - lander.pad)) < 0.2
    _, u = lander.command(45.0, p, np.zeros(3))
    assert u[0] == 0.0 and u[1] == 0.0 and u[2] == lander.u_lo[2]  # idle


def test_loss_flight_commits_once_and_asks_to_disarm_when_landed() -> None:
    sc = load_scenario(str(CUBE8))
    loss = RunnerLoss(HZ, 3.0)
    loss.observe(500, 400)
    flight = LossFlight(sc, sc.index_of(4), 4, loss)
    assert flight.setpoint(9.0, np.array([2.0, 0.4, 2.9]), np.zeros(3)) is not None  # hold
    assert not loss.landing and flight.lander is None
    assert flight.setpoint(10.0, np.array([2.0, 0.4, 2.9]), np.zeros(3)) is not None
    assert loss.landing and flight.lander is not None
    t_end = flight.lander.ref.t_end
    ground = flight.lander.ref.xi(t_end)[:3]
    assert not flight.disarm_due(t_end + 0.5, 0.0, True)  # not settled yet
    assert not flight.disarm_due(t_end + 1.0, 0.0, True)  # landed: idle starts
    assert flight.disarm_due(t_end + 2.0, 0.0, True)
    assert not flight.disarm_due(t_end + 2.5, 0.0, True)  # retried 2 s later
    assert not flight.disarm_due(t_end + 5.0, 0.0, False)  # disarmed
    assert ground[2] == pytest.approx(0.0)


class _Link:
    """The few VehicleLink members ModeRequests uses (unit test of one class): its real
    command queue, sending into a list."""

    def __init__(self) -> None:
        from offboard.daemon.mavlink.commands import VehicleCommands

        self.custom_mode, self.in_offboard, self.armed, self.failsafe_texts = 0, False, True, 0
        self.sent: list[Any] = []
        self.commands = VehicleCommands(3, self.sent.append)


def test_disarm_outcome_is_not_taken_for_an_arm() -> None:
    from offboard.daemon.mavlink.link import mavlink
    from offboard.daemon.mavlink.mode_requests import ModeRequests
    from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper

    link = _Link()
    keeper = OffboardKeeper(0.6, manual_start=True)
    modes = ModeRequests(link, keeper, 3)  # type: ignore[arg-type]
    modes.disarm()
    (sent,) = link.sent
    assert sent.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM and sent.param1 == 0
    assert sent.target_system == 3 and modes.disarming
    ack = mavlink.MAVLink_command_ack_message(
        mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_RESULT_DENIED, 0, 0, 3, 191
    )
    link.commands.on_ack(ack, 1.0)
    modes.collect(1.0)
    assert not modes.disarming and not keeper.arm_acked
    assert not link.commands  # collected and forgotten


@pytest.mark.parametrize(("text", "value"), [("3", 3.0), ("0", 0.0), ("2", 2.0), ("1", None),
                                             ("nan", None), ("inf", None), ("x", None),
                                             ("-3", None), ("3601", None)])
def test_loss_land_after_flag(text: str, value: float | None) -> None:
    from offboard.cli import loss_land_after

    assert loss_land_after(text) == value


def test_loss_flight_brakes_at_once_and_holds_where_the_loss_was_seen() -> None:
    """Lost at 2 m/s: the very first loss step already decelerates, and the point mass
    (with a constant push) stops within 0.75 m of where the loss was seen and stays there;
    no setpoint while truth is fresh, and a new loss holds at its own position."""
    sc = load_scenario(str(CUBE8))
    loss = RunnerLoss(HZ, 3.0)
    flight = LossFlight(sc, sc.index_of(5), 5, loss)
    p0, v0 = np.array([1.0, 2.0, 3.0]), np.array([2.0, 0.0, 0.0])
    assert flight.setpoint(1.0, p0, v0) is None  # not lost: the agent flies
    assert loss.observe(100, 100 - STALLED_PERIODS - 1) == "stalled"
    assert flight.setpoint(1.8, p0, v0) is not None
    hold = flight.flight
    assert hold is not None and flight.lander is None
    _, u = hold.command(1.82, p0, v0)
    assert u[0] < -1.0  # braking against the motion from the first step
    samples = []
    p, v, t, dt = p0.copy(), v0.copy(), 1.84, 0.02
    while t < 4.5:
        _, u = hold.command(t, p, v)
        v = v + (u + np.array([0.3, 0.0, 0.0])) * dt
        p = p + v * dt
        samples.append(p.copy())
        t += dt
    dist = np.linalg.norm(np.array(samples) - p0, axis=1)
    assert float(dist.max()) < 0.75 and float(dist[-1]) < 0.1
    assert loss.observe(120, 100 - STALLED_PERIODS - 1) == "lost"  # the stall goes on
    flight.setpoint(2.2, p, v)
    assert flight.flight is hold and loss.t_land is not None  # same hold, a land time now
    assert loss.observe(200, 199) == "back" and flight.setpoint(4.0, p, v) is None
    assert loss.observe(300, 300 - RUNNER_LOST_PERIODS - 1) == "lost"  # a new stall
    p1 = np.array([4.0, 4.0, 2.0])
    flight.setpoint(6.0, p1, np.zeros(3))
    assert flight.flight is not hold and flight.flight is not None
    assert np.allclose(flight.flight.ref.xi(6.0)[:3], p1)
