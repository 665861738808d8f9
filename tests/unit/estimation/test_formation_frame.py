"""The formation frame of a turning formation (offboard.estimation.formation_frame): the yaw
read from the leaders' reference states, and jets turned between the frames, checked
against a timed mission plan and finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.estimation.yaw_turn import extrapolate, turn_xi, yaw_jet_from_offset
from swarm_common.mission.config import parse_mission
from swarm_common.mission.plan import Limits, build_plan

SHAPE = np.array([[4.0, 0.0, 6.0], [4.0, 4.0, 6.0], [0.0, 0.0, 2.0], [0.0, 4.0, 2.0],
                  [0.0, 0.0, 6.0], [4.0, 4.0, 2.0]])
LIMITS = Limits(3.0, 1.0, 2.0, 0.5, 0.5)


def plan():
    cfg = parse_mission({"speed_mps": 1.5, "max_speed_mps": 3.0, "max_accel_mps2": 1.0,
                         "max_jerk_mps3": 2.0, "waypoint": [
                             {"centroid": [2.0, 2.0, 4.0], "hold_s": 1.0},
                             {"centroid": [10.0, 6.0, 5.0], "yaw_deg": 90.0, "scale": 1.4},
                             {"centroid": [4.0, 12.0, 4.0], "yaw_deg": -30.0, "scale": 0.8}]})
    return build_plan(cfg, SHAPE, LIMITS)


def times(pl, n=60):
    return np.linspace(0.2, pl.end_s - 0.2, n)


@pytest.mark.full
def test_the_yaw_read_from_two_leaders_is_the_plans():
    pl = plan()
    r0 = complex(*(SHAPE[1, :2] - SHAPE[0, :2]))
    for t in times(pl):
        a, b = pl.agent_xi(t, 0), pl.agent_xi(t, 1)
        r = [complex(b[3 * d] - a[3 * d], b[3 * d + 1] - a[3 * d + 1]) for d in range(4)]
        got = yaw_jet_from_offset(r, math.atan2(r0.imag, r0.real))
        want = pl.yaw_jet(t)
        assert math.remainder(got[0] - want[0], 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
        np.testing.assert_allclose(got[1:], want[1:], rtol=1e-7, atol=1e-9)


def test_turning_there_and_back_is_the_identity():
    pl = plan()
    rng = np.random.default_rng(3)
    for t in times(pl, 20):
        xi = rng.standard_normal(12)
        f = np.empty(12)
        turn_xi(xi, pl.yaw_jet(t), -1.0, f)
        back = np.empty(12)
        turn_xi(f, pl.yaw_jet(t), 1.0, back)
        np.testing.assert_allclose(back, xi, rtol=0, atol=1e-12)


def test_a_turned_jet_is_the_jet_of_the_turned_path():
    """In the formation frame an agent's desired path is ζ(t) = R(−ψ(t)) p(t): its turned
    jet's derivatives must match central differences of the turned positions and
    velocities (h = 1e-4 s: truncation ~1e-8 of m/s³ scale values)."""
    pl = plan()
    h = 1e-4

    def zeta(t):
        out = np.empty(12)
        turn_xi(pl.agent_xi(t, 3), pl.yaw_jet(t), -1.0, out)
        return out

    for t in times(pl, 40):
        z, zp, zm = zeta(t), zeta(t + h), zeta(t - h)
        for d in range(3):
            fd = (zp[3 * d:3 * d + 3] - zm[3 * d:3 * d + 3]) / (2 * h)
            np.testing.assert_allclose(z[3 * d + 3:3 * d + 6], fd, atol=2e-6)


def test_in_the_formation_frame_the_shape_stands_still_up_to_scale():
    """What the frame is for: turned into it, the agents' offsets from the centroid keep the
    shape's directions (the bearings are the fixed ones) however the formation turns."""
    pl = plan()
    q = SHAPE - SHAPE.mean(axis=0)
    for t in times(pl, 30):
        c, s, _ = pl.pose_jet(t)
        yaw = pl.yaw_jet(t)
        for i in range(len(SHAPE)):
            z = np.empty(12)
            turn_xi(pl.agent_xi(t, i), yaw, -1.0, z)
            cf = np.empty(12)
            turn_xi(np.concatenate([c[0], c[1], c[2], c[3]]), yaw, -1.0, cf)
            np.testing.assert_allclose(z[:3] - cf[:3], s[0] * q[i], atol=1e-9)


def test_extrapolation_is_exact_for_a_cubic():
    jet = np.array([0.3, -0.2, 0.5, 1.5])
    dt = 0.02
    f = lambda t: 0.3 - 0.2 * t + 0.25 * t**2 + 0.25 * t**3  # noqa: E731
    got = extrapolate(jet, dt)
    assert got[0] == pytest.approx(f(dt), abs=1e-15)
    assert got[1] == pytest.approx(-0.2 + 0.5 * dt + 0.75 * dt**2, abs=1e-15)
    assert got[2] == pytest.approx(0.5 + 1.5 * dt, abs=1e-15)
