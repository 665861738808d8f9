"""vehicle_sim.physics.dynamics: the documented behaviour of the vehicle model (paper §2.2,
§5.1)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import CUBE8

from swarm_common.enums import Role
from swarm_common.scenario.model import AgentSpec, load_scenario, with_overrides
from vehicle_sim.physics.dynamics import SwarmDynamics, external_disturbance, regressor


@pytest.fixture(scope="module")
def cube8():
    return load_scenario(CUBE8)


def quiet(sc, **zeta):
    """No external disturbance and no unmodeled dynamics (optionally some ζ columns)."""
    z = [0.0] * 6
    for k, v in zeta.items():
        z[int(k[1:])] = v
    return with_overrides(sc, disturbance={"amplitude_n": 0.0},
        unmodeled={"zeta_nominal": z, "zeta_spread": 0.0},
    )


def with_agents(sc, positions, velocities=None):
    vel = velocities or [[0.0, 0.0, 0.0]] * len(positions)
    agents = tuple(
        AgentSpec(
            id=k + 1,
            role=Role.LEADER if k < 2 else Role.FOLLOWER,
            position=np.array(p, dtype=float),
            velocity=np.array(v, dtype=float),
            vertex=np.array([k, 0, 0], dtype=float),
        )
        for k, (p, v) in enumerate(zip(positions, vel, strict=True))
    )
    return dataclasses.replace(sc, agents=agents)


def test_hover_thrust_holds_altitude(cube8):
    dyn = SwarmDynamics(quiet(cube8))
    p0 = dyn.p.copy()
    for i in range(dyn.n):
        dyn.set_command(i, 0.0, 0.0, 0.0, dyn.hold_thrust())
    dyn.advance(1000)  # 5 s
    np.testing.assert_allclose(dyn.p[:, :2], p0[:, :2] + 5.0 * dyn.v[:, :2], atol=1e-9)
    # vertical: followers 3..6 start with vz = +-0.6 and keep it (no force); leaders stay
    np.testing.assert_allclose(dyn.p[:2], p0[:2], atol=1e-9)
    assert np.allclose(dyn.v[:, 2], cube8.initial_velocities()[:, 2], atol=1e-9)


def _time_constant(trace, target, dt):
    """Estimate tau from a first-order step response sampled every dt (exact samples)."""
    taus = []
    for k, x in enumerate(trace, start=1):
        frac = x / target
        if 0.2 < frac < 0.9:
            taus.append(-k * dt / math.log(1.0 - frac))
    return float(np.median(taus))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_attitude_step_time_constant(cube8, axis):
    dyn = SwarmDynamics(quiet(cube8))
    cmd = [0.0, 0.0, 0.0]
    cmd[axis] = 0.3
    dyn.set_command(0, *cmd, dyn.hold_thrust())
    trace = []
    for _ in range(200):
        dyn.step()
        trace.append(dyn.att[0, axis])
    tau_cfg = getattr(cube8.vehicle, "tau_yaw_s" if axis == 2 else "tau_rollpitch_s")
    assert _time_constant(trace, 0.3, dyn.dt) == pytest.approx(tau_cfg, rel=0.10)
    # 63 % rise time, read off the samples, within 10 % too
    k63 = next(k for k, x in enumerate(trace, start=1) if x >= 0.3 * (1 - math.exp(-1)))
    assert k63 * dyn.dt == pytest.approx(tau_cfg, rel=0.10, abs=dyn.dt)


def test_thrust_step_time_constant(cube8):
    dyn = SwarmDynamics(quiet(cube8))
    f0 = dyn.hold_thrust()
    dyn.set_command(0, 0.0, 0.0, 0.0, f0 + 10.0)
    trace = []
    for _ in range(100):
        dyn.step()
        trace.append(dyn.thrust[0] - f0)
    assert _time_constant(trace, 10.0, dyn.dt) == pytest.approx(
        cube8.vehicle.tau_thrust_s, rel=0.10
    )


def test_tilt_and_thrust_clamped(cube8):
    dyn = SwarmDynamics(quiet(cube8))
    dyn.set_command(0, 2.0, -2.0, 0.5, 1e6)
    lim = math.radians(cube8.vehicle.tilt_max_deg)
    assert dyn.cmd_att[0, 0] == pytest.approx(lim) and dyn.cmd_att[0, 1] == pytest.approx(-lim)
    assert dyn.cmd_thrust[0] == pytest.approx(cube8.vehicle.thrust_max_n)
    dyn.set_command(1, math.nan, 0.0, 0.0, 10.0)  # ignored
    assert dyn.cmd_thrust[1] == pytest.approx(dyn.hold_thrust())


def test_tilt_accelerates_horizontally(cube8):
    """Pitch θ > 0 (FLU, nose down about y... ENU Euler ZYX) tilts thrust towards +x."""
    dyn = SwarmDynamics(quiet(cube8))
    th = 0.2
    dyn.set_command(0, 0.0, th, 0.0, dyn.hold_thrust() / math.cos(th))
    dyn.advance(400)  # 2 s, attitude settled after ~1 s
    a = dyn.thrust_accel()[0]
    assert a[0] == pytest.approx(dyn.g * math.tan(th), rel=1e-3)
    assert a[2] == pytest.approx(dyn.g, rel=1e-3)
    assert dyn.v[0, 0] > 1.0


def test_external_disturbance_effect(cube8):
    sc = with_overrides(cube8, unmodeled={"zeta_nominal": [0.0] * 6, "zeta_spread": 0.0})
    dyn = SwarmDynamics(sc)
    a, w = sc.disturbance.amplitude_n, sc.disturbance.omega_rad_s
    for t in (0.0, 0.7, 2.0):
        expect = a * np.array([math.cos(w * t), math.sin(w * t), math.sin(w * t)]) / dyn.mass
        np.testing.assert_allclose(dyn.lumped_accel(t)[3], expect, atol=1e-12)
    np.testing.assert_allclose(external_disturbance(0.0, a, w), [a, 0, 0])
    # integrated over 1 s from rest at hover: Δv ≈ ∫ d/m dt
    sc2 = with_agents(sc, [[0, 0, 5], [10, 0, 5]])
    dyn = SwarmDynamics(sc2)
    dyn.advance(200)
    dv_expected = a / dyn.mass * np.array([math.sin(1.0), 1 - math.cos(1.0), 1 - math.cos(1.0)])
    np.testing.assert_allclose(dyn.v[0], dv_expected, rtol=0.02, atol=1e-4)


def test_drag_terms_effect(cube8):
    # linear drag only: a vehicle coasting at 2 m/s slows as exp(-ζ1 t)
    z1 = 0.5
    sc = with_agents(quiet(cube8, z1=z1), [[0, 0, 5], [50, 0, 5]], [[2.0, 0, 0], [0, 0, 0]])
    dyn = SwarmDynamics(sc)
    dyn.advance(400)  # 2 s
    assert dyn.v[0, 0] == pytest.approx(2.0 * math.exp(-z1 * 2.0), rel=0.01)
    # quadratic drag decelerates more at higher speed
    sc = with_agents(quiet(cube8, z2=0.1), [[0, 0, 5], [50, 0, 5]], [[4.0, 0, 0], [1.0, 0, 0]])
    dyn = SwarmDynamics(sc)
    dyn.step()
    acc = (dyn.v[:, 0] - np.array([4.0, 1.0])) / dyn.dt
    assert acc[0] == pytest.approx(-0.1 * 16.0, rel=0.01)
    assert acc[1] == pytest.approx(-0.1 * 1.0, rel=0.01)
    # ground effect: pushes up near the ground, fades with height
    phi_low = regressor(np.array([0, 0, 0.1]), np.zeros(3), 0.8)
    phi_high = regressor(np.array([0, 0, 5.0]), np.zeros(3), 0.8)
    assert phi_low[2, 4] > 0.8 and phi_high[2, 4] < 0.01
    # the lumped term equals Φ ζ + d/m
    dyn = SwarmDynamics(cube8)
    phi = regressor(dyn.p, dyn.v, cube8.unmodeled.ground_effect_height_m)
    expect = (
        np.einsum("nij,nj->ni", phi, dyn.zeta)
        + external_disturbance(
            0.0, cube8.disturbance.amplitude_n, cube8.disturbance.omega_rad_s
        )
        / dyn.mass
    )
    np.testing.assert_allclose(dyn.lumped_accel(), expect)


def test_ground_contact(cube8):
    sc = with_agents(quiet(cube8), [[0, 0, 2.0], [10, 0, 0.5]], [[1.0, 0, 0], [0, 0, 0]])
    dyn = SwarmDynamics(sc)
    dyn.set_command(0, 0.0, 0.0, 0.0, 0.0)
    dyn.set_command(1, 0.0, 0.0, 0.0, 0.0)
    zmin = np.inf
    for _ in range(600):
        dyn.step()
        zmin = min(zmin, dyn.p[:, 2].min())
    assert zmin >= 0.0
    np.testing.assert_allclose(dyn.p[:, 2], 0.0)
    np.testing.assert_allclose(dyn.v, 0.0)  # friction stops a landed vehicle
    assert dyn.on_ground().all()
    # thrust above weight lifts it off again
    dyn.set_command(0, 0.0, 0.0, 0.0, 1.5 * dyn.hold_thrust())
    dyn.advance(100)
    assert dyn.p[0, 2] > 0.05 and not dyn.on_ground()[0]


def test_collision_counting(cube8):
    # 1 and 2 fly through each other head-on; 3 stays away
    sc = with_agents(
        quiet(cube8),
        [[-1.0, 0, 5], [1.0, 0, 5], [0, 20, 5]],
        [[1.0, 0, 0], [-1.0, 0, 0], [0, 0, 0]],
    )
    dyn = SwarmDynamics(sc)
    dyn.advance(400)  # they cross at t = 1 s, apart again at 2 s
    assert dyn.collisions == 1
    t, a, b = dyn.collision_pairs[0]
    assert (a, b) == (1, 2)
    r = cube8.vehicle.collision_radius_m
    assert t == pytest.approx((2.0 - r) / 2.0, abs=2 * dyn.dt)  # gap 2 m, closing at 2 m/s
    assert dyn.min_pair_distance() > r


def test_held_until_released(cube8):
    dyn = SwarmDynamics(cube8, held=True)
    p0 = dyn.p.copy()
    dyn.advance(100)
    np.testing.assert_array_equal(dyn.p, p0)
    dyn.release(2)  # agent 3 leaves with its spawn velocity (0, 0, 0.6)
    dyn.advance(20)
    assert dyn.p[2, 2] > p0[2, 2]
    np.testing.assert_array_equal(np.delete(dyn.p, 2, axis=0), np.delete(p0, 2, axis=0))


def test_deterministic_for_seed(cube8):
    def run(seed):
        dyn = SwarmDynamics(cube8, seed=seed)
        rng = np.random.default_rng(5)
        for _ in range(50):
            for i in range(dyn.n):
                dyn.set_command(i, *rng.uniform(-0.2, 0.2, 3), dyn.hold_thrust() * 1.05)
            dyn.advance(4)
        return dyn.p.copy(), dyn.zeta.copy()

    p1, z1 = run(7)
    p2, z2 = run(7)
    p3, z3 = run(8)
    np.testing.assert_array_equal(p1, p2)
    np.testing.assert_array_equal(z1, z2)
    assert not np.array_equal(z1, z3) and not np.array_equal(p1, p3)


def test_state_assigned_in_other_types_flies_the_same(cube8):
    """The physics' kernels are called through sites typed at their first call
    (swarm_common.jit.CallSite). State assigned afterwards in other types (an int time,
    a numpy int32 step count, a list of held flags, float32 positions, an F-order ζ,
    float32 and list commands) flies exactly as the same state in float64: an array of
    another dtype or layout would be misread by the compiled entry point, so the arrays
    are converted before the call (a scalar the entry point converts itself)."""
    a, b = SwarmDynamics(cube8, seed=3), SwarmDynamics(cube8, seed=3)
    for d in (a, b):
        d.advance_period(4)  # every site typed by its first call
    steps = 1000 * round(1.0 / cube8.physics_dt)  # 1000 s of mission time
    t = steps * a.dt
    assert t == int(t)
    rng = np.random.default_rng(11)
    p32 = (a.p + rng.normal(0.0, 0.3, a.p.shape)).astype(np.float32)
    held = rng.uniform(size=a.n) < 0.5
    a.t, a.step_count, a.p, a.held = t, steps, p32.astype(np.float64), held
    b.t, b.step_count, b.p, b.held = int(t), np.int32(steps), p32, [int(h) for h in held]
    b.zeta = np.asfortranarray(b.zeta)
    att = rng.uniform(-0.3, 0.3, (3, a.n)).astype(np.float32)  # exact in float64 too
    thrust = cube8.vehicle.mass_kg * 9.81 * (1.0 + rng.uniform(-0.3, 0.3, a.n))
    a.set_commands(*att.astype(np.float64), thrust)
    b.set_commands(*att, list(thrust))
    # the same code in one process: the same bits
    assert np.array_equal(a.lumped_accel(), b.lumped_accel())
    assert np.array_equal(a.lumped_accel(int(t) + 2), b.lumped_accel(int(t) + 2))
    for _ in range(3):
        assert a.advance_period(5) == b.advance_period(5)
        for name in ("p", "v", "att", "thrust"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert (a.t, a.step_count, a.collisions) == (b.t, b.step_count, b.collisions)
    assert a.t == pytest.approx(t + 15 * a.dt, rel=1e-12)
