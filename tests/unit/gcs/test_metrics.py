"""gcs.report.metrics on synthetic series: true barrier, fixed-window tracking, phases."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.mission.run_output import empty_series
from gcs.report.metrics import (
    METRIC_KEYS,
    PHASES,
    SafetySpec,
    barrier_metrics,
    compute_metrics,
    formation_time,
    min_distance_by_phase,
    window_tracking,
)
from gcs.report.verdict import pair_barrier
from swarm_common.enums import QPStatus

TAU, D = 0.8, 0.5
DT = 0.1


def _head_on(n: int = 41, speed: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two agents on the x axis, approaching head-on at ``speed`` each from 4 m apart, so
    Δp = 4 − 2·speed·t and Δv = −2·speed: h(t) = Δp² − 2τ·2·speed·Δp − D²."""
    t = np.arange(n) * DT
    gap = 4.0 - 2 * speed * t
    p = np.zeros((n, 2, 3))
    v = np.zeros((n, 2, 3))
    p[:, 1, 0] = gap
    v[:, 0, 0], v[:, 1, 0] = speed, -speed
    p[:, 0, 0] = 0.0  # frame of agent 0 (only differences matter)
    return t, p, v


def test_pair_barrier_matches_closed_form_and_crosses_zero() -> None:
    t, p, v = _head_on()
    h = pair_barrier(p, v, TAU, D)
    gap = 4.0 - t  # speed 0.5: closing at 1 m/s
    expected = gap**2 + 2 * TAU * (-1.0) * gap - D**2
    np.testing.assert_allclose(h[:, 0], expected, rtol=0, atol=1e-12)
    assert h[0, 0] > 0 and h[-1, 0] < 0  # gap 4 m -> 0 m: the barrier crosses zero
    # positive root of gap² − 1.6 gap − 0.25: gap* = 0.8 + sqrt(0.89)
    crossing_gap = 0.8 + np.sqrt(0.64 + 0.25)
    n_neg = int(np.sum(gap < crossing_gap - 1e-12))
    m = barrier_metrics(p, v, TAU, D)
    assert m["barrier_violation_steps"] == n_neg == m["barrier_violation_pair_steps"]
    assert m["h_min"] == pytest.approx(float(expected.min()))


def test_barrier_velocity_term_counts_even_outside_d_safe() -> None:
    """Far enough apart (gap > D) yet closing fast: h < 0 by the velocity term alone."""
    p = np.zeros((1, 2, 3))
    v = np.zeros((1, 2, 3))
    p[0, 1, 0] = 1.0
    v[0, 1, 0] = -1.0  # closing at 1 m/s: h = 1 − 1.6 − 0.25 < 0 with distance 1 m > D
    m = barrier_metrics(p, v, TAU, D)
    assert m["h_min"] == pytest.approx(1.0 - 1.6 - 0.25)
    assert m["barrier_violation_steps"] == 1


def test_barrier_counts_every_pair_in_a_step() -> None:
    """Three agents at one point: three pairs negative, one step."""
    p = np.zeros((2, 3, 3))
    v = np.zeros((2, 3, 3))
    p[0] = [[0, 0, 0], [5, 0, 0], [0, 5, 0]]  # step 0: all far apart
    m = barrier_metrics(p, v, TAU, D)
    assert m["barrier_violation_steps"] == 1
    assert m["barrier_violation_pair_steps"] == 3
    assert m["h_min"] == pytest.approx(-D**2)


def test_fixed_window_tracking_sees_an_excursion_after_the_deadline() -> None:
    """A 2 s, 0.5 m excursion at t = 30 s must show up; the old conditional window
    (after the last excursion) reported only the calm tail."""
    t = np.arange(0, 40, DT)
    err = np.full((len(t), 2), 0.02)
    err[t < 5.0] = 1.0  # forming
    out = (t >= 30.0 - 1e-9) & (t < 32.0 - 1e-9)
    err[out, 1] = 0.5
    r = window_tracking(t, err, 20.0, DT)
    assert r["tracking_max_m"] == pytest.approx(0.5)
    assert r["tracking_time_above_0p1_s"] == pytest.approx(2.0)
    w = err[t >= 20.0 - 1e-9]
    assert r["tracking_rms_m"] == pytest.approx(float(np.sqrt(np.mean(w**2))))
    rms = r["tracking_rms_m"]
    assert rms is not None and rms > 0.1  # the outage weighs in the RMS
    # formation_time keeps its definition: the last step back inside the tolerance
    assert formation_time(t, err) == pytest.approx(32.0)


def test_fixed_window_excludes_the_formation_phase() -> None:
    t = np.arange(0, 30, DT)
    err = np.full((len(t), 1), 0.03)
    err[t < 19.95] = 2.0
    r = window_tracking(t, err, 20.0, DT)
    assert r["tracking_max_m"] == pytest.approx(0.03)
    assert r["tracking_time_above_0p1_s"] == 0.0


def test_run_shorter_than_deadline_has_null_tracking() -> None:
    t = np.arange(0, 15, DT)
    r = window_tracking(t, np.full((len(t), 3), 0.01), 20.0, DT)
    assert r == {"tracking_rms_m": None, "tracking_max_m": None,
                 "tracking_time_above_0p1_s": None}


def test_min_distance_by_phase() -> None:
    t = np.arange(0, 30, DT)
    md = 3.0 - 0.01 * t
    md[50] = 0.4  # t = 5 s, formation phase
    r = min_distance_by_phase(t, md, 20.0)
    assert set(r) == set(PHASES)
    assert r["takeoff"] is None and r["landing"] is None
    assert r["formation"] == pytest.approx(0.4)
    assert r["mission"] == pytest.approx(3.0 - 0.01 * t[-1])
    short = min_distance_by_phase(t[:100], md[:100], 20.0)
    assert short["mission"] is None and short["formation"] == pytest.approx(0.4)


def test_compute_metrics_schema_and_clipped_steps() -> None:
    t, p, v = _head_on()
    n = 2
    s = empty_series(t, n)
    s.p[:], s.v[:], s.p_des[:] = p, v, p
    s.min_dist[:] = np.linalg.norm(p[:, 0] - p[:, 1], axis=1)
    s.thrust[:] = 17.0
    s.h_min[:], s.solve_us[:] = 1.0, 10.0
    s.fallback[:] = QPStatus(QPStatus.SOLVED).degraded
    s.input_clipped[::10, 1] = True  # rows 0, 10, 20, ... of agent 1
    zeta = np.ones((n, 6))
    spec = SafetySpec(TAU, D, 2.0)
    m = compute_metrics(s, [1], DT, 1.8, 9.81, 0, zeta, zeta, 0, 1.0, 4.0, spec)
    assert tuple(m) == METRIC_KEYS
    assert m["input_clipped_steps"] == 5  # rows 0, 10, 20, 30, 40
    assert m["h_min"] < 0 < m["barrier_violation_steps"]
    assert m["tracking_max_m"] == 0.0 and m["tracking_time_above_0p1_s"] == 0.0
    extra = compute_metrics(s, [1], DT, 1.8, 9.81, 0, zeta, zeta, 0, 1.0, 4.0, spec,
                            extra={"mission_completed": True, "ref_est_max_m": 0.25})
    assert tuple(extra) == METRIC_KEYS
    assert extra["mission_completed"] is True and extra["ref_est_max_m"] == 0.25
    assert m["mission_completed"] is None and m["ref_est_max_m"] is None
    unknown = compute_metrics(s, [1], DT, 1.8, 9.81, 0, zeta, zeta, 0, 1.0, 4.0,
                              SafetySpec(TAU, D, 2.0, clipped_known=False))
    assert unknown["input_clipped_steps"] is None
