"""Neighbour data ageing in the agent (Departure 16, communication.max_age_s,
docs/estimation.md §4): leaders exact through any outage, followers with an error bound."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from offboard.estimation.peer_table import XI, Z1, Z2
from offboard.estimation.predictor import NeighbourPredictor, error_accel_gain
from offboard.estimation.reference import exo_propagator, xi_a, xi_p, xi_v
from offboard.records import NeighbourEstimate

OMEGA = 2 * np.pi * 0.2
DT = 0.02
FOL = (7.0, 3.0)  # k_p', k_v of the followers' assumed loop (cube8: ks λ + kp/kd, λ + ks)
LEAD = (4.0, 3.0)
IDS = list(range(10))  # the scenario's agent ids, equal to their indices here


def _xi0() -> np.ndarray:
    """A leader-like desired state: p*(t) = p0 + A(1 − cos ωt) at t = 0.3 s."""
    amp = np.array([0.8, 0.4, 0.2])
    t = 0.3
    xi = np.zeros(12)
    xi[0:3] = np.array([4.0, 0.0, 6.0]) + amp * (1 - np.cos(OMEGA * t))
    xi[3:6] = amp * OMEGA * np.sin(OMEGA * t)
    xi[6:9] = amp * OMEGA**2 * np.cos(OMEGA * t)
    xi[9:12] = -amp * OMEGA**3 * np.sin(OMEGA * t)
    return xi


def _est(aid: int, t: float, z1: np.ndarray, z2: np.ndarray, xi: np.ndarray,
         leader: bool) -> NeighbourEstimate:
    return NeighbourEstimate(aid, t, z1, z2, np.zeros(3), xi, leader)


@pytest.mark.full
def test_leader_exact_through_a_long_outage() -> None:
    """A leader on the exosystem with a PD offset: the prediction 5 s later equals the
    exosystem's state plus the PD loop's decayed offset, and is never dropped (max_age 1 s)."""
    pred = NeighbourPredictor(IDS, OMEGA, DT, FOL, LEAD, max_age=1.0)
    xi = _xi0()
    off_p, off_v = np.array([0.05, -0.02, 0.01]), np.array([0.0, 0.03, -0.01])
    pred.ingest({1: _est(1, 0.0, xi_p(xi) + off_p, xi_v(xi) + off_v, xi, True)}, comm_ok=True)
    for k in range(1, 251):  # a 5 s outage; every step predicted, every 10th checked
        t = k * DT
        if k % 10:
            assert pred.get_at(1, t) is not None
            continue
        got = pred.get_at(1, t)
        assert got is not None
        xi_t = exo_propagator(OMEGA, t) @ xi
        m = expm(np.array([[0.0, 1.0], [-LEAD[0], -LEAD[1]]]) * t)
        assert np.allclose(got[2], xi_t, atol=1e-9)
        assert np.allclose(got[0], xi_p(xi_t) + m[0, 0] * off_p + m[0, 1] * off_v, atol=1e-9)
        assert np.allclose(got[1], xi_v(xi_t) + m[1, 0] * off_p + m[1, 1] * off_v, atol=1e-9)
        assert pred.bound_at(1, t) == 0.0
    # the exosystem reproduces the leader trajectory itself
    t = 5.0
    p_true = np.array([4.0, 0.0, 6.0]) + np.array([0.8, 0.4, 0.2]) * (
        1 - np.cos(OMEGA * (0.3 + t)))
    assert np.allclose(xi_p(exo_propagator(OMEGA, t) @ xi), p_true, atol=1e-9)


def test_follower_bound_grows_and_drops() -> None:
    pred = NeighbourPredictor(IDS, OMEGA, DT, FOL, LEAD, max_age=1.0, a_max=10.0, drop_bound=0.5)
    xi = _xi0()
    pred.ingest({5: _est(5, 0.0, xi_p(xi), xi_v(xi), xi, False)}, comm_ok=True)
    assert pred.bound_at(5, 0.0) == 0.0 and pred.bound_at(9, 0.0) is None
    b1, b2 = pred.bound_at(5, 0.1), pred.bound_at(5, 0.2)
    assert b1 is not None and b2 is not None and np.isclose(b2, 4 * b1)  # ½ a_dev age²
    a_star = np.sqrt(np.sum(xi_a(xi) ** 2) + np.sum(xi[9:12] ** 2) / OMEGA**2)
    assert np.isclose(b1, 0.5 * (10.0 + a_star) * 0.01)
    # on its desired motion the prediction is the exosystem's
    got = pred.get_at(5, 0.2)
    assert got is not None and np.allclose(got[0], xi_p(exo_propagator(OMEGA, 0.2) @ xi))
    # dropped once the bound exceeds drop_bound: ½ (10 + ā*) age² > 0.5 m
    t_drop = np.sqrt(2 * 0.5 / (10.0 + a_star))
    assert pred.get_at(5, t_drop - 0.02) is not None
    assert pred.get_at(5, t_drop + 0.02) is None
    # a follower far from its target has a larger bound (the assumed loop accelerates it)
    far = _est(6, 0.0, xi_p(xi) + np.array([3.0, 0.0, 0.0]), xi_v(xi), xi, False)
    pred.ingest({6: far}, comm_ok=True)
    bf = pred.bound_at(6, 0.1)
    assert bf is not None and bf > b1 + 0.5 * error_accel_gain(*FOL) * 3.0 * 0.01 - 1e-12
    # during an outage nothing is ingested; a fresh message brings it back
    pred.ingest({5: _est(5, 5.0, xi_p(xi), xi_v(xi), xi, False)}, comm_ok=False)
    assert pred.get_at(5, 5.0) is None
    pred.ingest({5: _est(5, 5.0, xi_p(xi), xi_v(xi), xi, False)}, comm_ok=True)
    assert pred.get_at(5, 5.0) is not None and pred.bound_at(5, 5.0) == 0.0


def test_max_age_caps_followers() -> None:
    pred = NeighbourPredictor(IDS, OMEGA, DT, FOL, LEAD, max_age=0.1, a_max=0.0, drop_bound=1e9)
    xi = _xi0()
    pred.ingest({5: _est(5, 0.0, xi_p(xi), xi_v(xi), xi, False)}, comm_ok=True)
    assert pred.get_at(5, 0.1) is not None and pred.get_at(5, 0.12) is None


@pytest.mark.full
def test_error_accel_gain_bounds_the_loop() -> None:
    """c_r bounds |[−k_p, −k_v] e^{As} x| / |x| over s, for random x and s."""
    kp, kv = FOL
    c = error_accel_gain(kp, kv)
    a = np.array([[0.0, 1.0], [-kp, -kv]])
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(300):
        x = rng.normal(size=2)
        s = rng.uniform(0, 3)
        worst = max(worst, abs(np.array([-kp, -kv]) @ expm(a * s) @ x) / np.linalg.norm(x))
    assert worst <= c and c < 1.5 * np.hypot(kp, kv)


def test_follower_bound_holds_on_simulated_data() -> None:
    """A follower whose true acceleration deviates from the assumed loop (held, saturated,
    disturbed) within a_max: the prediction error stays inside the bound at every step."""
    a_max = 6.0
    pred = NeighbourPredictor(IDS, OMEGA, DT, FOL, LEAD, a_max=a_max, drop_bound=1e9)
    rng = np.random.default_rng(7)
    kp, kv = FOL
    for trial in range(10):
        xi = _xi0()
        p = xi_p(xi) + rng.normal(0, 1.5, 3)
        v = xi_v(xi) + rng.normal(0, 0.5, 3)
        pred.ingest({5: _est(5, float(trial), p.copy(), v.copy(), xi, False)}, comm_ok=True)
        h = 2e-3
        held = rng.uniform() < 0.5
        xi_t = xi.copy()
        step_exo = exo_propagator(OMEGA, h)
        for k in range(1, 501):  # 1 s, fine Euler; check at control steps
            nominal = xi_a(xi_t) - kp * (p - xi_p(xi_t)) - kv * (v - xi_v(xi_t))
            a = rng.uniform(-1, 1, 3) * a_max / np.sqrt(3) if held else nominal
            a = a if np.linalg.norm(a) <= a_max else a * a_max / np.linalg.norm(a)
            p, v = p + h * v + 0.5 * h * h * a, v + h * a
            xi_t = step_exo @ xi_t
            if k % 10 == 0:
                t = trial + k * h
                got, b = pred.get_at(5, t), pred.bound_at(5, t)
                assert got is not None and b is not None
                assert np.linalg.norm(got[0] - p) <= b + 1e-6


def test_a_stamp_off_by_rounding_is_current_data() -> None:
    """A follower's estimate stamped t_k + dt by its sender, read at (k + 1)·dt by the
    receiver (6·0.02 + 0.02 < 7·0.02 by one rounding): current data, bound 0, returned as
    received, and its a_dev is never computed; a millisecond later it is aged."""
    t_sent, t_read = 6 * DT + DT, 7 * DT
    assert 0.0 < t_read - t_sent < 1e-15
    pred = NeighbourPredictor(IDS, OMEGA, DT, FOL, LEAD, max_age=1.0)
    xi = _xi0()
    e = _est(2, t_sent, xi_p(xi) + 0.3, xi_v(xi) - 0.2, xi, False)
    pred.ingest({2: e}, comm_ok=True)
    got = pred.get_at(2, t_read)
    assert got is not None
    for a, b in zip(got, (e.z1, e.z2, e.xi), strict=True):  # as received, in the table
        assert np.array_equal(a, b) and np.shares_memory(a, pred.table.rows)
    assert pred.bound_at(2, t_read) == 0.0 and pred.velocity_bound_at(2, t_read) == 0.0
    rows, have = pred.predict_rows(np.array([2, 4]), t_read)
    assert rows is pred.table.rows and have[2] and not have[4]  # 4 never heard
    assert not pred._a_dev  # nothing computed for current data
    later = t_read + 1e-3
    age = later - t_sent
    assert pred.bound_at(2, later) == 0.5 * pred.a_dev_of(e.z1, e.z2, e.xi) * age * age > 0.0


def test_an_outage_computes_nothing_new_in_the_control_loop() -> None:
    """The predictor computes c_r and every propagator up to max_age when it is made, so
    predicting a leader and a follower through an outage as long as max_age adds nothing
    to the process-wide caches (left to the first outage, c_r's sweep alone took ~15 ms
    inside one control step); the cached values are those the functions give."""
    import offboard.estimation.predictor as predictor

    for cache in (predictor._EXO_CACHE, predictor._ERR_CACHE, predictor._CR_CACHE):
        cache.clear()
    omega, fol = OMEGA * 1.01, (7.5, 3.0)  # keys no other test has filled
    pred = NeighbourPredictor(IDS, omega, DT, fol, LEAD, max_age=0.5, drop_bound=1e9)
    sizes = [len(c) for c in (predictor._EXO_CACHE, predictor._ERR_CACHE,
                              predictor._CR_CACHE)]
    assert sizes[0] >= 26 and sizes[1] >= 52 and sizes[2] == 1
    xi = _xi0()
    pred.ingest({1: _est(1, 0.0, xi_p(xi), xi_v(xi), xi, True),
                 5: _est(5, 0.0, xi_p(xi) + 0.1, xi_v(xi), xi, False)}, comm_ok=True)
    peers = np.array([1, 5], dtype=np.int64)
    for k in range(1, 26):  # 0.5 s of silence
        rows, have = pred.predict_rows(peers, k * DT)
        assert have[1] and have[5], k
    assert [len(c) for c in (predictor._EXO_CACHE, predictor._ERR_CACHE,
                             predictor._CR_CACHE)] == sizes
    assert np.array_equal(pred.exo(7), exo_propagator(omega, 7 * DT))
    assert np.array_equal(pred.err(False, 7),
                          expm(np.array([[0.0, 1.0], [-fol[0], -fol[1]]]) * 7 * DT))
    assert predictor._CR_CACHE[fol] == error_accel_gain(*fol)


def _numpy_prediction(
    pred: NeighbourPredictor, j: int, t: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The prediction in numpy (the reference of the compiled predict_row_into): the
    exosystem carries ξ n periods, the error loop's propagator m carries (e1, e2)."""
    n = pred._periods_ahead(j, t)
    if n is None:
        return None
    r = pred.table.rows[j]
    z1, z2, xi = r[Z1], r[Z2], r[XI]
    if n == 0:
        return z1, z2, xi
    xi_n = pred.exo(n) @ xi
    m = pred.err(bool(pred.table.leader[j]), n)
    e1, e2 = z1 - xi_p(xi), z2 - xi_v(xi)
    return (xi_p(xi_n) + m[0, 0] * e1 + m[0, 1] * e2,
            xi_v(xi_n) + m[1, 0] * e1 + m[1, 1] * e2, xi_n)


def test_predictions_equal_the_numpy_formulation_bit_for_bit() -> None:
    """predict_rows and get_at write each stale row with a compiled kernel
    (predict_row_into) from numpy's propagator product; the reference forms the same
    prediction in numpy. Over random stamps (current, a fraction of a period old, aged,
    past max_age) of leaders and followers, the rows, get_at's answers and the usable mask
    agree exactly with it, and each case occurs. Regrouping one addition fails it."""
    rng = np.random.default_rng(11)
    seen = {"current": 0, "predicted": 0, "dropped": 0}
    for trial in range(200):
        pred = NeighbourPredictor(IDS, OMEGA, DT, FOL, LEAD, max_age=0.6, drop_bound=0.8)
        t_now = 3.0
        ests = {}
        for aid in IDS[1:]:
            xi = _xi0() + rng.normal(0.0, 0.3, 12)
            age = float(rng.choice([0.0, 0.004, rng.uniform(0.0, 0.9)]))
            ests[aid] = _est(aid, t_now - age, xi_p(xi) + rng.normal(0.0, 0.2, 3),
                             xi_v(xi) + rng.normal(0.0, 0.2, 3), xi, bool(aid % 3 == 0))
        pred.ingest(ests, comm_ok=True)
        peers = np.array(IDS[1:], dtype=np.int64)
        rows, have = pred.predict_rows(peers, t_now)
        rows, have = rows.copy(), have.copy()
        for j in IDS[1:]:
            ref = _numpy_prediction(pred, j, t_now)
            got = pred.get_at(j, t_now)
            assert have[j] == (ref is not None) == (got is not None), (trial, j)
            if ref is None or got is None:
                seen["dropped"] += 1
                continue
            for k, cols in enumerate((Z1, Z2, XI)):
                assert np.array_equal(rows[j, cols], ref[k]), (trial, j, k)
                assert np.array_equal(got[k], ref[k]), (trial, j, k)
            age = t_now - ests[j].t
            seen["current" if round(age / DT) == 0 else "predicted"] += 1
    assert min(seen.values()) > 100, seen
