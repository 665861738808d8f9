"""The rest-to-rest profile and the timed mission plan, checked numerically: finite
differences for every derivative, dense sampling for every limit and peak."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_common.mission.config import MissionConfig, MissionError, Waypoint
from swarm_common.mission.plan import MIN_LEG_S, Limits, build_plan
from swarm_common.mission.profile import (
    SIGMA1_PEAK,
    SIGMA2_PEAK,
    SIGMA3_PEAK,
    sigma_jet,
    sigma_jets,
)

# an irregular, non-planar 6-agent shape (m); its mean is (0.5, 0.5, 5.5)
SHAPE = np.array(
    [
        [3.0, 0.0, 5.0],
        [-2.0, 1.0, 5.5],
        [0.5, -2.5, 6.0],
        [1.0, 3.0, 5.0],
        [-1.5, -1.0, 6.5],
        [2.0, 2.5, 5.0],
    ]
)
LIMITS = Limits(
    max_speed_mps=5.0, max_accel_mps2=1.5, max_jerk_mps3=3.0, floor_m=0.5, min_separation_m=1.0
)
MARGIN_LOW = 1.0 / 1.02**3 - 1e-3  # the tightest limit ratio is at least this (T minimal)


def mission(*wps: Waypoint, speed: float = 1.5, start_s: float = 2.0) -> MissionConfig:
    return MissionConfig(waypoints=tuple(wps), speed_mps=speed, start_s=start_s)


# leg 0: translate; leg 1: yaw + scale + translate (with a hold); leg 2: no motion;
# leg 3: pure yaw of -450 deg with a per-leg cruise speed
CFG = mission(
    Waypoint((4.0, 0.0, 6.0), 1.0, 0.0, 1.0),
    Waypoint((10.0, -6.0, 8.0), 1.8, 120.0, 2.5),
    Waypoint((10.0, -6.0, 8.0), 1.8, 120.0, 0.0),
    Waypoint((10.0, -6.0, 8.0), 1.8, -330.0, 0.0, 0.5),
)


@pytest.fixture(scope="module")
def plan():
    return build_plan(CFG, SHAPE, LIMITS)


def rz(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------- profile
def test_sigma_ends_and_clamp():
    assert sigma_jet(0.0) == (0.0, 0.0, 0.0, 0.0)
    assert sigma_jet(1.0) == (1.0, 0.0, 0.0, 0.0)
    assert sigma_jet(-0.3) == (0.0, 0.0, 0.0, 0.0)
    assert sigma_jet(1.7) == (1.0, 0.0, 0.0, 0.0)
    # approaching the ends from inside: every derivative -> 0 (sigma''' ~ 840 d, the
    # slowest), sigma -> 0 / 1; d = 1e-12 from the end, tol 1e-8
    for tau, end in ((1e-12, 0.0), (1.0 - 1e-12, 1.0)):
        s = sigma_jet(tau)
        assert abs(s[0] - end) < 1e-8 and max(abs(x) for x in s[1:]) < 1e-8
    assert sigma_jet(0.5)[0] == pytest.approx(0.5, abs=1e-15)


def test_sigma_derivatives_match_central_differences():
    h = 1e-5
    for tau in np.linspace(0.01, 0.99, 37):
        lo, hi, mid = sigma_jet(tau - h), sigma_jet(tau + h), sigma_jet(tau)
        for k in range(3):
            fd = (hi[k] - lo[k]) / (2 * h)
            # truncation ~ h^2 |sigma^(k+3)| / 6 < 1e-6 for these polynomials
            assert fd == pytest.approx(mid[k + 1], abs=1e-5), (tau, k)


def test_sigma_jets_agrees_with_sigma_jet():
    taus = np.array([-1.0, 0.0, 0.123, 0.5, 0.77, 1.0, 2.0])
    got = sigma_jets(taus)
    assert got.shape == (7, 4)
    for row, tau in zip(got, taus, strict=True):
        assert np.allclose(row, sigma_jet(float(tau)), rtol=0, atol=1e-12)


def test_peak_constants_match_dense_sampling():
    jets = sigma_jets(np.linspace(0.0, 1.0, 200_001))
    for k, peak in ((1, SIGMA1_PEAK), (2, SIGMA2_PEAK), (3, SIGMA3_PEAK)):
        sampled = np.max(np.abs(jets[:, k]))
        assert sampled <= peak * (1 + 1e-12)
        assert sampled == pytest.approx(peak, rel=1e-8)
    assert np.all(np.diff(jets[:, 0]) >= -1e-15)  # monotone (up to rounding): no overshoot


# ---------------------------------------------------------------- timing
def test_timeline(plan):
    legs = plan.legs
    assert [leg.index for leg in legs] == [0, 1, 2, 3]
    assert legs[0].t0 == CFG.start_s
    for k, leg in enumerate(legs):
        assert plan.arrival_s[k] == pytest.approx(leg.t0 + leg.duration_s, abs=1e-12)
        assert plan.departure_s[k] == pytest.approx(plan.arrival_s[k] + CFG.waypoints[k].hold_s)
        if k:
            assert leg.t0 == plan.departure_s[k - 1]
    assert legs[2].duration_s == 0.0  # no motion at all
    assert all(leg.duration_s >= MIN_LEG_S for k, leg in enumerate(legs) if k != 2)
    assert plan.end_s == plan.departure_s[-1]
    assert plan.transit_window == (plan.departure_s[0], plan.arrival_s[-1])


def test_one_waypoint_window_and_holds_outside_the_mission():
    cfg = mission(Waypoint((1.0, 2.0, 7.0), 1.0, 30.0, 4.0))
    p = build_plan(cfg, SHAPE, LIMITS)
    assert p.transit_window == (p.arrival_s[0], p.arrival_s[0])
    assert p.end_s == pytest.approx(p.arrival_s[0] + 4.0)
    before = p.all_xi(cfg.start_s - 1.0)
    assert np.allclose(before[:, :3], SHAPE, atol=1e-12) and not before[:, 3:].any()
    c, s, y = p.pose_jet(-5.0)
    assert np.allclose(c[0], SHAPE.mean(axis=0)) and s[0] == 1.0 and y[0] == 0.0
    assert not (c[1:].any() or s[1:].any() or y[1:].any())
    after = p.all_xi(p.end_s + 100.0)
    q = SHAPE - SHAPE.mean(axis=0)
    want = np.array([1.0, 2.0, 7.0]) + q @ rz(math.radians(30.0)).T
    assert np.allclose(after[:, :3], want, atol=1e-12) and not after[:, 3:].any()


def test_arrivals_reach_each_waypoint(plan):
    q = SHAPE - SHAPE.mean(axis=0)
    assert np.allclose(plan.shape_offsets, q)
    for k, w in enumerate(CFG.waypoints):
        for t in (plan.arrival_s[k], plan.departure_s[k]):
            assert np.allclose(plan.centroid_at(t), w.centroid, atol=1e-12)
            want = np.array(w.centroid) + w.scale * q @ rz(math.radians(w.yaw_deg)).T
            xi = plan.all_xi(t)
            assert np.allclose(xi[:, :3], want, atol=1e-9)
            assert np.abs(xi[:, 3:]).max() < 1e-9  # at rest at a waypoint
            assert plan.yaw_jet(t)[0] == pytest.approx(math.radians(w.yaw_deg), abs=1e-12)


def _leg_times(plan, k: int, n: int) -> np.ndarray:
    leg = plan.legs[k]
    return leg.t0 + np.linspace(0.0, 1.0, n) * leg.duration_s


def _limit_cases() -> list[tuple[Limits, int | None]]:
    """LIMITS, then each of speed, acceleration, jerk made the binding one (its index)."""

    def lim(v: float, a: float, j: float) -> Limits:
        return Limits(v, a, j, LIMITS.floor_m, LIMITS.min_separation_m)

    return [
        (LIMITS, None),
        (lim(0.3, 50.0, 500.0), 0),
        (lim(15.0, 0.05, 500.0), 1),
        (lim(15.0, 50.0, 0.02), 2),
    ]


@pytest.mark.parametrize(("limits", "binding"), _limit_cases(), ids=["scenario", "v", "a", "j"])
def test_limits_hold_and_are_tight_under_dense_sampling(limits, binding):
    plan = build_plan(CFG, SHAPE, limits)
    cruise = [w.speed_mps or CFG.speed_mps for w in CFG.waypoints]
    lim = np.array([limits.max_speed_mps, limits.max_accel_mps2, limits.max_jerk_mps3])
    for k, leg in enumerate(plan.legs):
        if leg.duration_s == 0.0:
            continue
        xi = np.array([plan.all_xi(t) for t in _leg_times(plan, k, 5000)])  # (5000, N, 12)
        peaks = np.array(
            [np.linalg.norm(xi[..., 3 * m : 3 * m + 3], axis=-1).max() for m in (1, 2, 3)]
        )
        assert np.all(peaks <= lim * (1 + 1e-6)), (k, peaks)
        cvel = np.array([np.linalg.norm(plan.pose_jet(t)[0][1]) for t in _leg_times(plan, k, 5000)])
        assert cvel.max() <= cruise[k] * (1 + 1e-6)
        # T is the smallest: some limit (or the cruise speed) is nearly reached
        ratios = [*(peaks / lim), cvel.max() / cruise[k]]
        assert max(ratios) >= MARGIN_LOW or leg.duration_s == MIN_LEG_S, (k, ratios)
        if binding is not None:
            assert ratios[binding] >= MARGIN_LOW, (k, ratios)


def _fd_check(f, t: float, h: float) -> None:
    """Central differences of f's p, v, a blocks against its v, a, j blocks."""
    lo, hi, mid = f(t - h), f(t + h), f(t)
    fd = (hi - lo) / (2 * h)
    for m in range(3):
        got = mid[..., 3 * (m + 1) : 3 * (m + 2)]
        want = fd[..., 3 * m : 3 * (m + 1)]
        # truncation h^2 |d^(m+4) p| / 6 with h = 1e-4 s, rounding 1e-16 |p| / h: < 1e-6
        assert np.allclose(got, want, rtol=1e-6, atol=2e-6), (t, m, got - want)


def test_agent_xi_matches_finite_differences(plan):
    for k in (0, 1, 3):
        for t in _leg_times(plan, k, 41)[1:-1]:
            for i in range(len(SHAPE)):
                _fd_check(lambda tt, i=i: plan.agent_xi(tt, i), t, 1e-4)
    # and across the whole mission, every agent at once, holds included
    for t in np.linspace(plan.legs[0].t0 - 1.0, plan.end_s + 1.0, 97):
        _fd_check(plan.all_xi, t, 1e-4)


def test_all_xi_rows_are_agent_xi(plan):
    t = plan.legs[1].t0 + 0.37 * plan.legs[1].duration_s
    rows = plan.all_xi(t)
    assert rows.shape == (len(SHAPE), 12)
    for i in range(len(SHAPE)):
        assert np.array_equal(rows[i], plan.agent_xi(t, i))


def test_pose_jet_matches_finite_differences_and_the_agents(plan):
    h = 1e-4
    q = plan.shape_offsets
    for t in _leg_times(plan, 1, 23)[1:-1]:
        (c, s, y), lo, hi = plan.pose_jet(t), plan.pose_jet(t - h), plan.pose_jet(t + h)
        for cur, a, b in zip((c, s, y), lo, hi, strict=True):
            fd = (b[:3] - a[:3]) / (2 * h)
            assert np.allclose(cur[1:], fd, rtol=1e-6, atol=2e-6)
        # agent positions are c + s Rz(psi) q at the same instant
        assert np.allclose(plan.all_xi(t)[:, :3], c[0] + s[0] * q @ rz(y[0]).T, atol=1e-12)
    assert np.array_equal(plan.yaw_jet(t), y) and np.array_equal(plan.centroid_at(t), c[0])


def test_leg_boundaries_are_continuous(plan):
    bounds = sorted({b for leg in plan.legs for b in (leg.t0, leg.arrival_s, leg.departure_s)})
    for tb in bounds:
        left = plan.all_xi(float(np.nextafter(tb, -np.inf)))
        here = plan.all_xi(tb)
        right = plan.all_xi(float(np.nextafter(tb, np.inf)))
        assert np.abs(left - here).max() < 1e-9, tb
        assert np.abs(right - here).max() < 1e-9, tb


def test_a_pure_yaw_leg_is_timed_by_the_outer_agents():
    ring = np.array(
        [
            [4.0 * math.cos(a), 4.0 * math.sin(a), 5.0]
            for a in np.linspace(0, 2 * math.pi, 8, endpoint=False)
        ]
    )
    center = ring.mean(axis=0)
    cfg = mission(
        Waypoint(tuple(center), 1.0, 0.0), Waypoint(tuple(center), 1.0, 90.0), start_s=0.0
    )
    p = build_plan(cfg, ring, LIMITS)
    assert p.legs[0].duration_s == 0.0  # already there
    leg = p.legs[1]
    assert leg.duration_s > MIN_LEG_S
    xi = np.array([p.all_xi(t) for t in _leg_times(p, 1, 5000)])
    lim = np.array([LIMITS.max_speed_mps, LIMITS.max_accel_mps2, LIMITS.max_jerk_mps3])
    peaks = np.array([np.linalg.norm(xi[..., 3 * m : 3 * m + 3], axis=-1).max() for m in (1, 2, 3)])
    assert np.all(peaks <= lim * (1 + 1e-6)) and max(peaks / lim) >= MARGIN_LOW
    assert all(np.abs(p.pose_jet(t)[0][1:]).max() == 0.0 for t in _leg_times(p, 1, 50))
    # a bigger ring turns slower
    big = build_plan(cfg, center + 2.0 * (ring - center), LIMITS)
    assert big.legs[1].duration_s > leg.duration_s * 1.2


def test_the_cruise_speed_bounds_a_long_translation():
    cfg = mission(
        Waypoint((0.5, 0.5, 5.5)),
        Waypoint((200.5, 0.5, 5.5), speed_mps=0.8),
        speed=1.5,
        start_s=0.0,
    )
    p = build_plan(cfg, SHAPE, LIMITS)
    speeds = [np.linalg.norm(p.pose_jet(t)[0][1]) for t in _leg_times(p, 1, 5001)]
    assert max(speeds) <= 0.8 * (1 + 1e-6) and max(speeds) >= 0.8 / 1.02 - 1e-3


def test_refuses_a_waypoint_below_the_floor():
    # agent 4 sits 1.0 m above the mean (z 6.5 vs 5.5); agent 0 at 0.5 m below it
    cfg = mission(Waypoint((0.0, 0.0, 5.0)), Waypoint((0.0, 0.0, 1.2), 2.0))
    with pytest.raises(MissionError) as info:
        build_plan(cfg, SHAPE, LIMITS)
    msg = str(info.value)
    assert msg.startswith("mission.waypoint[1]:") and "agent 0" in msg and "z = 0.200" in msg
    assert "\n" not in msg
    build_plan(
        mission(Waypoint((0.0, 0.0, 5.0)), Waypoint((0.0, 0.0, 1.5), 2.0)), SHAPE, LIMITS
    )  # z = 0.5 exactly on the floor: allowed


def test_refuses_a_waypoint_with_agents_too_close():
    # the closest pair of SHAPE: agents 3 and 5, |(1,0.5,0)| = 1.118 m at scale 1
    d = math.hypot(1.0, 0.5)
    ok = mission(Waypoint((0.0, 0.0, 6.0), 1.0 / d + 1e-6))
    build_plan(ok, SHAPE, LIMITS)
    bad = mission(Waypoint((0.0, 0.0, 6.0)), Waypoint((0.0, 0.0, 6.0), 0.8))
    with pytest.raises(MissionError) as info:
        build_plan(bad, SHAPE, LIMITS)
    msg = str(info.value)
    assert msg.startswith("mission.waypoint[1]:") and "agents 3 and 5" in msg
    assert f"{0.8 * d:.3f} m" in msg


def test_bad_inputs_are_refused():
    with pytest.raises(MissionError):
        build_plan(CFG, SHAPE[:, :2], LIMITS)
    with pytest.raises(MissionError):
        build_plan(CFG, np.array([[0.0, 0.0, math.nan]]), LIMITS)
    with pytest.raises(MissionError, match="max_jerk_mps3"):
        Limits(5.0, 1.5, 0.0, 0.0, 0.0)
