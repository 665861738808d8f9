"""The dcbf transient speed limit (offboard.safety.dcbf.speed_rows, docs/safety.md §5i):
its prediction against a dense integration of the lag model, its rows against a direct
evaluation of the predicted relative velocity, the clipped rows' feasibility, and a closed
loop in which a follower asked to sprint keeps ‖v − v*‖ ≤ v_t."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import CUBE8

from offboard.safety.base import W_SAFE
from offboard.safety.dcbf.filter import DcbfFilter, input_set_of
from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.speed_rows import TransientLimit
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from swarm_common.enums import QPStatus
from swarm_common.scenario.model import load_scenario

DT = 0.02


def _limit(v_t: float, err: float = 1.0) -> tuple[TransientLimit, object]:
    sc = load_scenario(CUBE8)
    veh = sc.vehicle
    tau = np.array([veh.tau_rollpitch_s, veh.tau_rollpitch_s, veh.tau_thrust_s])
    lag = LagCoefficients.of(tau, veh.tau_rollpitch_s + DT)
    uset = input_set_of(sc.controller, veh)
    return TransientLimit(v_t, lag, err, uset), uset


def _dense_velocity(v: np.ndarray, a0: np.ndarray, w: np.ndarray, u: np.ndarray,
                    tau: np.ndarray, t_end: float, n: int = 20000) -> np.ndarray:
    """v(T) of v̇ = a + w, ȧ = (u − a)/τ, by exact per-substep lag updates."""
    h = t_end / n
    a, vel = a0.copy(), v.copy()
    e = np.exp(-h / tau)
    for _ in range(n):
        a_next = u + (a - u) * e
        # ∫ a over the substep, exactly
        vel = vel + (u * h + (a - u) * tau * (1.0 - e)) + w * h
        a = a_next
    return vel


def test_prediction_matches_the_lag_model():
    lim, _ = _limit(2.0)
    rng = np.random.default_rng(3)
    tau = np.array([0.15, 0.15, 0.03])
    for _ in range(5):
        v, a0, u = rng.normal(0, 2, 3), rng.normal(0, 3, 3), rng.normal(0, 3, 3)
        w = rng.normal(0, 0.1, 3)  # inside W_SAFE = 0.5 m/s²: not saturated
        assert np.linalg.norm(w) < 0.5
        xi = rng.normal(0, 1, 12)
        lim.prepare(v, a0, w, xi)
        t = lim.T
        v_star = xi[3:6] + xi[6:9] * t + 0.5 * xi[9:12] * t * t
        direct = _dense_velocity(v, a0, w, u, tau, t) - v_star
        assert np.allclose(lim.predicted(u), direct, atol=1e-9)


def test_cut_rows_are_the_tangent_planes_of_the_ball():
    """gᵀu ≥ r ⇔ nᵀê_T(u) ≤ b wherever the row is not clipped; the cube rows keep the ball."""
    lim, _ = _limit(1.5)
    rng = np.random.default_rng(7)
    g, rhs = np.zeros((10, 3)), np.zeros(10)
    lim.prepare(np.array([1.2, -0.4, 0.1]), np.zeros(3), np.zeros(3), np.zeros(12))
    n = lim.direction(np.zeros(3))
    assert lim.write([n], False, g, rhs, 0) == 1
    need = (float(n @ lim.e0) - lim.bound) / float(np.linalg.norm(n * lim.cv))
    assert rhs[0] == pytest.approx(need)  # reachable: not clipped
    for _ in range(2000):
        u = rng.uniform(-8, 8, 3)
        lhs, val = float(g[0] @ u) - rhs[0], float(n @ lim.predicted(u)) - lim.bound
        assert (lhs >= 0.0) == (val <= 0.0) or abs(val) < 1e-9
    lim.prepare(np.array([0.6, -0.3, 0.1]), np.zeros(3), np.zeros(3), np.zeros(12))
    assert lim.write([], True, g, rhs, 0) == 6
    assert np.all(g[:6] @ lim.u_b > rhs[:6])  # reachable in one horizon: none clipped
    for _ in range(2000):
        u = rng.uniform(-8, 8, 3)
        if np.all(g[:6] @ u >= rhs[:6]):
            assert np.linalg.norm(lim.predicted(u)) <= lim.bound + 1e-9


def test_clipped_rows_keep_a_point_of_the_input_set():
    """A follower far faster than v_t: the rows ask what the input set can do, and u_b
    (in the set) keeps every one."""
    lim, uset = _limit(1.0)
    lim.prepare(np.array([6.0, -5.0, 3.0]), np.zeros(3), np.zeros(3), np.zeros(12))
    assert lim.excess(lim.u_b) > 0.0  # cannot reach the ball in one horizon
    cuts = [lim.direction(np.zeros(3)), lim.direction(lim.u_b), np.array([0.0, 1.0, 0.0])]
    g, rhs = np.zeros((9, 3)), np.zeros(9)
    k = lim.write(cuts, True, g, rhs, 0)
    assert uset.contains(lim.u_b, 1e-9)
    assert np.all(g[:k] @ lim.u_b >= rhs[:k] - 1e-12)


def _run_sprint(v_t: float, v0: float, steps: int) -> tuple[np.ndarray, list[QPStatus]]:
    """One follower, no pairs, whose nominal control asks the most the set allows toward
    +x (a target far away), v* = 0: the lag model flown step by step under the filter."""
    sc = load_scenario(CUBE8)
    ctl = dataclasses.replace(sc.controller, max_transient_speed_mps=v_t)
    filt = DcbfFilter(ctl, -np.full(3, 8.0), np.full(3, 8.0), np.zeros(2, dtype=bool))
    filt.configure(sc.vehicle, DT)
    assert filt.speed is not None
    tau = np.array([0.15, 0.15, 0.03])
    v, a = np.array([v0, 0.0, 0.0]), np.zeros(3)
    clf = ClfTerms(0.0, 0.0, np.zeros(3), np.array([6.0, 0.0, 0.0]))
    speeds, status = [], []
    for _ in range(steps):
        filt.speed.prepare(v, a, np.zeros(3), np.zeros(12))
        res = filt.solve_limited(clf.u_nom, clf, 0, math.inf, np.zeros(3), v, False, 0.0)
        status.append(res.qp_status)
        v = _dense_velocity(v, a, np.zeros(3), res.u, tau, DT, 200)
        a = res.u + (a - res.u) * np.exp(-DT / tau)
        speeds.append(float(np.linalg.norm(v)))
    return np.array(speeds), status


def test_a_sprinting_follower_keeps_the_limit():
    speeds, status = _run_sprint(1.2, 0.0, 300)
    assert speeds.max() <= 1.2  # the guarantee: ‖v − v*‖ ≤ v_t (v* = 0 here)
    assert speeds[-1] >= 0.9 * (1.2 - 1.0 * 0.17)  # and it does fly near the limit
    assert not any(s.degraded for s in status)


def test_a_follower_starting_faster_slows_down_without_slack():
    speeds, status = _run_sprint(1.0, 4.0, 200)
    assert not any(s.degraded for s in status)  # the clipped rows need no slack
    assert np.all(np.diff(speeds[:40]) < 0.0)  # it brakes from the first step
    assert speeds[-1] <= 1.0


def test_the_limit_gives_way_only_as_far_as_a_pair_row_needs():
    """A pair row that asks for more speed than v_t allows (a neighbour closing from behind):
    the row holds without slack, and the command is the one nearest the limit's braking
    command u_b that keeps it, not the nominal command through the row alone (which let a
    follower sprint at its nominal law's pace while the limit was off)."""
    sc = load_scenario(CUBE8)
    ctl = dataclasses.replace(sc.controller, max_transient_speed_mps=1.0)
    filt = DcbfFilter(ctl, -np.full(3, 8.0), np.full(3, 8.0), np.zeros(2, dtype=bool))
    filt.configure(sc.vehicle, DT)
    lim = filt.speed
    assert lim is not None
    v = np.array([1.0, 0.0, 0.0])  # at the limit, v* = 0
    lim.prepare(v, np.zeros(3), np.zeros(3), np.zeros(12))
    out = filt.rows_out()
    out.g[0], out.rhs[0] = np.array([1.0, 0.0, 0.0]), 3.0  # u_x ≥ 3 m/s²
    filt.note_rows(np.array([1]), np.zeros(0, dtype=np.int64), False)
    clf = ClfTerms(0.0, 0.0, np.zeros(3), np.array([6.0, 4.0, 0.0]))
    assert lim.excess(np.array([3.0, 0.0, 0.0])) > 0.0  # the row and the limit conflict
    res = filt.solve_limited(clf.u_nom, clf, 1, math.inf, np.zeros(3), v, False, 0.0)
    assert not res.qp_status.degraded
    assert res.u[0] >= 3.0 - 1e-6  # the pair row holds
    assert lim.excess(res.u) < lim.excess(clf.u_nom)  # slower than the nominal command
    # the nearest point to u_b of {u_x ≥ 3} ∩ the input set, against a dense sample of it
    _, uset = _limit(1.0)
    rng = np.random.default_rng(11)
    best = math.inf
    for u in rng.uniform(-8.0, 8.0, (40000, 3)):
        if u[0] >= 3.0 and uset.contains(u, 0.0):
            best = min(best, float(np.linalg.norm(u - lim.u_b)))
    assert float(np.linalg.norm(res.u - lim.u_b)) <= best + 1e-6


def _reference_prepare(lim: TransientLimit, v: np.ndarray, a0: np.ndarray, w: np.ndarray,
                       xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The step's (ê_T at u = 0, u_b) in numpy, as the module docstring writes them."""
    t = lim.T
    n = float(np.linalg.norm(w))
    w = w * (W_SAFE / n) if n > W_SAFE else w
    v_star = xi[3:6] + xi[6:9] * t + 0.5 * xi[9:12] * (t * t)
    e0 = v + lim.ia * a0 + w * t - v_star
    return e0, lim.uset.project(-e0 / lim.cv)


def _reference_rows(lim: TransientLimit, cuts: list[np.ndarray], cube: bool
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The rows gᵀu ≥ r of the cuts and the inner cube, each scaled to a unit gradient and
    clipped to what u_b achieves, in numpy."""
    planes = [(n, lim.bound) for n in cuts]
    if cube:
        planes += [(s * e, lim.bound / math.sqrt(3.0)) for s in (1.0, -1.0) for e in np.eye(3)]
    g = np.array([-(n * lim.cv) / np.linalg.norm(n * lim.cv) for n, _ in planes]).reshape(-1, 3)
    need = np.array([(n @ lim.e0 - b) / np.linalg.norm(n * lim.cv) for n, b in planes])
    return g, np.minimum(need, g @ lim.u_b)


def test_the_compiled_rows_agree_with_numpy() -> None:
    """The compiled prepare and write against the numpy of the module docstring (1e-12):
    random states, disturbances over W_SAFE, zero to three cuts, with and without the cube."""
    lim, _ = _limit(3.0)
    rng = np.random.default_rng(12)
    for trial in range(500):
        v, a0 = rng.normal(0, 4, 3), rng.normal(0, 4, 3)
        w, xi = rng.normal(0, 6, 3), rng.normal(0, 3, 12)
        lim.prepare(v, a0, w, xi)
        e0, u_b = _reference_prepare(lim, v, a0, w, xi)
        np.testing.assert_allclose(lim.e0, e0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lim.u_b, u_b, rtol=0, atol=1e-12)
        cuts = [c / np.linalg.norm(c) for c in rng.normal(0, 1, (int(rng.integers(0, 4)), 3))]
        cube = trial % 3 == 0
        g, rhs = np.full((20, 3), 7.0), np.full(20, 7.0)
        k = lim.write(cuts, cube, g, rhs, 2)
        want_g, want_rhs = _reference_rows(lim, cuts, cube)
        assert k == len(want_rhs) == len(cuts) + 6 * cube
        np.testing.assert_allclose(g[2:2 + k], want_g, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rhs[2:2 + k], want_rhs, rtol=0, atol=1e-12)
        assert np.all(g[:2] == 7.0) and np.all(rhs[2 + k:] == 7.0)  # nothing else written


def test_rows_that_do_not_fit_are_refused() -> None:
    lim, _ = _limit(3.0)
    lim.prepare(np.ones(3), np.zeros(3), np.zeros(3), np.zeros(12))
    g, rhs = np.zeros((8, 3)), np.zeros(8)
    assert lim.write([np.array([1.0, 0.0, 0.0])], True, g, rhs, 1) == 7
    with pytest.raises(ValueError, match="do not fit"):
        lim.write([np.array([1.0, 0.0, 0.0])], True, g, rhs, 2)
