"""DCBF (docs/safety.md): prediction and ḣ against finite differences of the real inner-loop
model, the input polytope inside the true tilt cone / thrust limit, and a closed-loop
head-on pair at the input limit that the filter must brake."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from reference.dcbf_rows import dcbf_rows, ground_rows, predict

from offboard.inner_loop.attitude import InnerLoopModel, accel_from_attitude, setpoint_from_accel
from offboard.safety.dcbf.filter import GROUND_ACCEL_ERR, GROUND_GAMMA, input_set_of
from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.qp import DcbfQP
from offboard.safety.rcbf.clf_rcbf import ClfTerms, barrier
from swarm_common.scenario.model import load_scenario

SC = load_scenario(Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml")
VEH, CTL = SC.vehicle, SC.controller
DT, NSUB = SC.control_dt, SC.observer.substeps
TAU = np.array([VEH.tau_rollpitch_s, VEH.tau_rollpitch_s, VEH.tau_thrust_s])
NO_CLF = ClfTerms(V=0.0, lfv=0.0, lgv=np.zeros(3), u_nom=np.zeros(3))


def _fly(inner: InnerLoopModel, u: np.ndarray, p: np.ndarray, v: np.ndarray, steps: int,
         fine: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """Hold command u for ``steps`` control periods on the real lag model; return p, v, the
    realised acceleration and the fine trajectory [(p, v, a)] (semi-implicit Euler)."""
    sp = setpoint_from_accel(u, 0.0, VEH)
    traj = []
    a = np.zeros(3)
    for _ in range(steps * fine):
        a = inner.run(sp, 1)[-1]
        v = v + a * inner_dt(fine)
        p = p + v * inner_dt(fine)
        traj.append(np.concatenate([p, v, a]))
    return p, v, a, traj


def inner_dt(fine: int) -> float:
    return DT / fine


def _warm(u0: np.ndarray, fine: int = 20) -> InnerLoopModel:
    """An inner-loop model that has flown u0 for 0.1 s (non-zero realised acceleration)."""
    inner = InnerLoopModel(VEH, inner_dt(fine))
    _fly(inner, u0, np.zeros(3), np.zeros(3), 5, fine)
    return inner


@pytest.mark.parametrize("u", [np.array([2.0, -1.0, 0.5]), np.array([-3.0, 2.5, -1.0])])
def test_prediction_and_hdot_match_real_lag_dynamics(u: np.ndarray) -> None:
    fine = 20
    inner = _warm(np.array([-1.0, 0.5, 0.3]), fine)
    r, pt, y = inner.att
    a0 = accel_from_attitude(r, pt, y, inner.f, VEH.mass_kg, VEH.gravity_mps2)
    p0, v0 = np.array([3.0, 1.0, 0.5]), np.array([-1.5, 0.2, 0.1])  # Δp, Δv vs agent at rest
    steps = math.ceil((VEH.tau_rollpitch_s + DT) / DT)  # whole control periods ≥ τ_rp + dt
    horizon = steps * DT
    _, _, _, traj = _fly(inner, u, p0.copy(), v0.copy(), steps, fine)
    lag = LagCoefficients.of(TAU, horizon)
    pr = predict(p0[None], v0[None], a0, u, np.zeros((1, 3)), lag, CTL.tau_safe_s, CTL.d_safe_m)
    real = np.array(traj)
    p_t, v_t, a_t = real[-1, 0:3], real[-1, 3:6], real[-1, 6:9]
    # the per-axis linear lag model is exact up to the tilt/thrust coupling; its error is
    # what the acceleration error bound ē covers (docs/safety.md, assumption A3)
    e_bar = CTL.dcbf_accel_error_mps2
    assert np.linalg.norm(pr.dp[0] - p_t) <= 0.5 * e_bar * horizon**2
    assert np.linalg.norm(pr.dv[0] - v_t) <= e_bar * horizon
    assert np.linalg.norm(pr.da[0] - a_t) <= e_bar
    # ḣ of the barrier at the real state T ahead, against a central difference of the true h
    h_real = barrier(real[:, 0:3], real[:, 3:6], CTL.tau_safe_s, CTL.d_safe_m)
    now = predict(p_t[None], v_t[None], a_t, a_t, np.zeros((1, 3)), LagCoefficients.of(TAU, 0.0),
                  CTL.tau_safe_s, CTL.d_safe_m)
    assert abs(now.h[0] - h_real[-1]) < 1e-12
    hdot_fd = (h_real[-1] - h_real[-3]) / (2 * inner_dt(fine))
    assert abs(now.hdot[0] - hdot_fd) < 0.02 * max(1.0, abs(hdot_fd))
    assert abs(pr.h[0] - h_real[-1]) < 0.1  # m², the predicted h itself


def test_row_gradient_matches_finite_difference_of_prediction() -> None:
    lag = LagCoefficients.of(TAU, VEH.tau_rollpitch_s + DT)
    dp, dv = np.array([[2.0, 0.5, -0.3]]), np.array([[-1.0, 0.3, 0.2]])
    a0, u0, oth = np.array([0.5, -0.2, 1.0]), np.array([1.0, 0.0, -0.5]), np.zeros((1, 3))
    g1, g3 = CTL.dcbf_gamma_lin, CTL.dcbf_gamma_cubic

    def f(u: np.ndarray) -> float:
        pr = predict(dp, dv, a0, u, oth, lag, CTL.tau_safe_s, CTL.d_safe_m)
        return float(pr.hdot[0] + g1 * pr.h[0] + g3 * pr.h[0] ** 3)

    g, _ = dcbf_rows(dp, dv, a0, u0, oth, np.ones(1), lag, CTL.tau_safe_s, CTL.d_safe_m,
                        g1, g3, 0.0)
    eps = 1e-5
    fd = np.array([(f(u0 + eps * e) - f(u0 - eps * e)) / (2 * eps) for e in np.eye(3)])
    assert np.allclose(g[0], fd / np.linalg.norm(fd), atol=1e-6)

    def h_t(u: np.ndarray) -> float:
        return float(predict(dp, dv, a0, u, oth, lag, CTL.tau_safe_s, CTL.d_safe_m).h[0])

    fd = np.array([(h_t(u0 + eps * e) - h_t(u0 - eps * e)) / (2 * eps) for e in np.eye(3)])
    assert np.allclose(g[1], fd / np.linalg.norm(fd), atol=1e-6)


def test_polytope_is_inside_true_tilt_cone_and_thrust_limit() -> None:
    uset = input_set_of(CTL, VEH)
    a, lo, hi = uset.rows()
    rng = np.random.default_rng(3)
    pts = rng.uniform([-10, -10, -9], [10, 10, 18], size=(20000, 3))
    inside = pts[np.all((pts @ a.T <= hi) & (pts @ a.T >= lo), axis=1)]
    assert len(inside) > 1000
    th = math.radians(VEH.tilt_max_deg)
    for u in inside:
        thrust = u + np.array([0.0, 0.0, VEH.gravity_mps2])
        assert math.hypot(thrust[0], thrust[1]) <= thrust[2] * math.tan(th) + 1e-9
        assert VEH.mass_kg * np.linalg.norm(thrust) <= VEH.thrust_max_n + 1e-9
        sp = setpoint_from_accel(u, 0.0, VEH)  # the setpoint conversion leaves u unchanged
        real = accel_from_attitude(sp.roll, sp.pitch, sp.yaw, sp.thrust_n, VEH.mass_kg,
                                   VEH.gravity_mps2)
        assert np.max(np.abs(real - u)) < 1e-9
    # the cone's full-tilt points just outside the polygon edges are excluded
    far = np.array([(VEH.gravity_mps2 + 2.0) * math.tan(th) * 1.001, 0.0, 2.0])
    assert not uset.contains(far)


def test_head_on_pair_at_input_limit_is_braked() -> None:
    """Two agents, 50 Hz, real lag model, nominal input driving them at each other at the
    input limit; the filter must keep the true distance ≥ D and the true h ≥ 0."""
    fine = NSUB
    uset = input_set_of(CTL, VEH)
    lag = LagCoefficients.of(TAU, VEH.tau_rollpitch_s + DT)
    qps = [DcbfQP(2, uset, CTL.rho, CTL.clf_c) for _ in range(2)]
    inners = [InnerLoopModel(VEH, DT / fine) for _ in range(2)]
    p = [np.array([-4.0, 0.0, 5.0]), np.array([4.0, 0.05, 5.0])]
    v = [np.array([2.0, 0.0, 0.0]), np.array([-2.0, 0.0, 0.0])]
    a_real = [np.zeros(3), np.zeros(3)]
    u_prev = [np.zeros(3), np.zeros(3)]
    v_old = [x.copy() for x in v]
    h_true, d_true = [], []
    for _ in range(400):  # 8 s
        us = []
        for i in range(2):
            j = 1 - i
            dp, dv = (p[i] - p[j])[None], (v[i] - v[j])[None]
            a_j = ((v[j] - v_old[j]) / DT)[None]
            u_nom = uset.project(-dp[0] / np.linalg.norm(dp[0]) * 20.0)  # at the limit
            g, rhs = dcbf_rows(dp, dv, a_real[i], u_prev[i], a_j, np.array([0.5]), lag,
                                  CTL.tau_safe_s, CTL.d_safe_m, CTL.dcbf_gamma_lin,
                                  CTL.dcbf_gamma_cubic, CTL.dcbf_accel_error_mps2)
            h = float(barrier(dp, dv, CTL.tau_safe_s, CTL.d_safe_m)[0])
            us.append(qps[i].solve(u_nom, NO_CLF, g, rhs, h, -v[i]).u)
        v_old = [x.copy() for x in v]
        for i in range(2):
            assert uset.contains(us[i], tol=1e-6)
            sp = setpoint_from_accel(us[i], 0.0, VEH)
            for a in inners[i].run(sp, fine):
                v[i] = v[i] + a * DT / fine
                p[i] = p[i] + v[i] * DT / fine
            a_real[i], u_prev[i] = a, us[i]
        dp, dv = (p[0] - p[1])[None], (v[0] - v[1])[None]
        h_true.append(float(barrier(dp, dv, CTL.tau_safe_s, CTL.d_safe_m)[0]))
        d_true.append(float(np.linalg.norm(dp)))
    assert min(d_true) >= CTL.d_safe_m
    assert min(h_true) >= 0.0
    assert min(d_true) < 3.0  # the nominal input did push them together


def test_input_clipped_flag_and_neighbour_acceleration() -> None:
    from offboard.agent.base import CLIP_TOL
    from offboard.estimation.neighbour_accel import NeighbourAccel
    from offboard.inner_loop.attitude import InnerLoopModel
    from offboard.records import NeighbourEstimate

    inside, outside = np.array([2.0, 1.0, 0.0]), np.array([7.0, 0.0, -3.0])  # 30° cone
    for u, clipped in ((inside, False), (outside, True)):
        # bool (np.bool_ where the kernel runs un-jitted, NUMBA_DISABLE_JIT=1)
        assert bool(InnerLoopModel(VEH, 0.005).command(u, 0.0, 4, CLIP_TOL)[2]) is clipped
    acc = NeighbourAccel([1, 2], a_max=5.0)
    z = np.zeros(3)
    for t, vx in ((0.0, 0.0), (0.02, 0.04), (0.04, 1.0)):
        acc.ingest({2: NeighbourEstimate(2, t, z, np.array([vx, 0.0, 0.0]), z, np.zeros(12))})
        if t == 0.02:
            assert np.allclose(acc.rows(np.array([0, 1])), np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    assert np.allclose(acc.rows(np.array([1])), [[5.0, 0, 0]])  # 48 m/s² bounded to a_max


def test_error_margin_does_not_repel_a_pair_at_rest_outside_the_safe_distance() -> None:
    """Two agents at rest 2.83 m apart (a cube face's centre to a corner, side 4 m) pass
    under ē = 2 m/s² with u = 0: the ē margin enters α exactly (C1), not linearised at ĥ_T,
    where α'(ĥ_T) = γ1 + 3γ3ĥ_T² ≈ 10 1/s made it exceed α and forced ḣ_T > 0 (a repulsion
    out to ≈ 2.9 m that deadlocked swap_centre seed 4, docs/safety.md §4)."""
    lag = LagCoefficients.of(TAU, VEH.tau_rollpitch_s + DT)
    dp, dv = np.array([[2.0, 2.0, 0.0]]), np.zeros((1, 3))
    zero = np.zeros(3)
    g, rhs = dcbf_rows(dp, dv, zero, zero, np.zeros((1, 3)), np.array([0.5]), lag,
                          CTL.tau_safe_s, CTL.d_safe_m, CTL.dcbf_gamma_lin,
                          CTL.dcbf_gamma_cubic, 2.0)
    assert np.all(g @ zero >= rhs)
    # ... while a pair at rest near D still has to be pushed apart
    g, rhs = dcbf_rows(np.array([[0.6, 0.0, 0.0]]), dv, zero, zero, np.zeros((1, 3)),
                          np.array([0.5]), lag, CTL.tau_safe_s, CTL.d_safe_m,
                          CTL.dcbf_gamma_lin, CTL.dcbf_gamma_cubic, 2.0)
    assert not np.all(g @ zero >= rhs)


@pytest.mark.parametrize("vz0", [0.0, -3.0])
def test_ground_barrier_holds_a_full_down_command_above_the_floor(vz0: float) -> None:
    """One agent at 4 m, nominal input straight down at the input limit, 50 Hz, real lag
    model, a constant 0.8 m/s² downward disturbance the rows only know within ē: the true
    altitude must stay above the floor (and the agent must have come down towards it)."""
    fine = NSUB
    uset = input_set_of(CTL, VEH)
    lag = LagCoefficients.of(TAU, VEH.tau_rollpitch_s + DT)
    qp = DcbfQP(2, uset, CTL.rho, CTL.clf_c)
    inner = InnerLoopModel(VEH, DT / fine)
    floor, dist = 0.5, np.array([0.0, 0.0, -0.8])
    p, v = np.array([0.0, 0.0, 4.0]), np.array([0.0, 0.0, vz0])
    a_real = np.zeros(3)
    zs, hs = [], []
    for _ in range(400):  # 8 s
        g, rhs = ground_rows(float(p[2]), float(v[2]), float(a_real[2]), 0.0, floor, lag,
                             CTL.tau_safe_s, GROUND_GAMMA, GROUND_ACCEL_ERR)
        u = qp.solve(uset.project(np.array([0.0, 0.0, -20.0])), NO_CLF, g, rhs, 1.0, -v).u
        assert uset.contains(u, tol=1e-6)
        for a in inner.run(setpoint_from_accel(u, 0.0, VEH), fine):
            v = v + (a + dist) * DT / fine
            p = p + v * DT / fine
        a_real = a
        zs.append(float(p[2]))
        hs.append(float(p[2] - floor + CTL.tau_safe_s * v[2]))
    assert min(zs) > floor
    assert zs[-1] < 1.5  # it did descend toward the floor (not frozen far above it)
    assert min(hs) >= 0.0  # h_g(0) > 0 and the barrier keeps it so
