"""The replay's cursor and source (gcs.dashboard.view.replay, .replay_source), checked
numerically against a series: time -> frame, the speed ladder, stepping, the closest
approach, the events, the min-distance plot, and the view of a frame."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from conftest import CUBE8
from pymavlink.dialects.v20 import common as mavlink

from gcs.dashboard.view.replay import (
    HISTORY_PERIOD_S,
    SPEEDS,
    ReplayCursor,
    fmt_dist,
    series_problem,
)
from gcs.dashboard.view.replay_source import ReplayRun, ReplaySource
from gcs.mission.run_output import empty_series
from swarm_common.enums import AgentAlarm, VehicleMode
from swarm_common.scenario.model import load_scenario

DT = 0.02  # s, the control period of cube8
K = 150  # 3 s of steps


def series_t() -> np.ndarray:
    return np.arange(K) * DT  # as the runners make it


def min_dist() -> np.ndarray:
    t = series_t()
    return 2.0 + np.cos(2.1 * t) - 0.4 * np.exp(-((t - 1.7) ** 2) / 0.01)


def test_every_sample_time_and_its_ns_stamp_is_its_frame() -> None:
    t = series_t()
    c = ReplayCursor(t, min_dist())
    for k in range(K):
        assert c.frame_at(t[k]) == k
        assert c.frame_at(round(t[k] * 1e9) / 1e9) == k  # an event stamped in whole ns
        assert c.frame_at(t[k] + 0.6 * DT) == k  # between samples: the one before
    assert c.frame_at(-5.0) == 0 and c.frame_at(1e6) == K - 1


def test_playing_moves_with_the_wall_clock_times_the_speed() -> None:
    t = series_t()
    c = ReplayCursor(t, min_dist())
    assert c.speed == 1.0 and not c.paused and c.frame == 0
    c.advance(0.5)
    assert c.time == pytest.approx(0.5) and c.frame == 25
    c.faster()
    c.advance(0.25)  # x2: 0.5 s more
    assert c.frame == 50
    c.toggle_pause()
    c.advance(10.0)  # paused: stays
    assert c.frame == 50 and "paused" in c.state_text()
    c.toggle_pause()
    c.advance(100.0)  # past the end: stops on the last frame
    assert c.frame == K - 1 and c.paused and c.at_end and c.state_text().endswith("end")
    c.toggle_pause()  # play at the end: from the start again
    assert c.frame == 0 and not c.paused


def test_the_speed_ladder_stops_at_both_ends() -> None:
    c = ReplayCursor(series_t(), min_dist())
    seen = []
    for _ in range(10):
        c.faster()
        seen.append(c.speed)
    assert seen[:4] == [2.0, 4.0, 8.0, 16.0] and set(seen[4:]) == {16.0}
    for _ in range(10):
        c.slower()
    assert c.speed == 0.25 == SPEEDS[0] and SPEEDS[-1] == 16.0
    assert "x0.25" in c.state_text()


def test_a_step_is_one_frame_and_holds_the_replay() -> None:
    t = series_t()
    c = ReplayCursor(t, min_dist())
    c.advance(1.0)
    k = c.frame
    c.step(1)
    assert c.paused and c.frame == k + 1 and c.time == t[k + 1]
    c.step(-1)
    c.step(-1)
    assert c.frame == k - 1
    c.seek(0.0)
    c.step(-1)
    assert c.frame == 0
    c.seek(1e9)
    c.step(1)
    assert c.frame == K - 1


def test_closest_approach_is_the_smallest_min_dist() -> None:
    t, md = series_t(), min_dist()
    c = ReplayCursor(t, md)
    assert c.to_closest()
    assert c.frame == int(np.argmin(md)) and c.time == t[np.argmin(md)] and c.paused
    assert c.min_dist_now == c.run_min == float(md.min())
    assert f"dmin {fmt_dist(float(md.min()))}" in c.line_text()
    assert f"run min {fmt_dist(float(md.min()))}" in c.line_text()
    nan = np.full(K, np.nan)
    c = ReplayCursor(t, nan)
    assert not c.to_closest() and c.run_min is None and c.min_dist_now is None


def test_next_and_previous_event() -> None:
    t = series_t()
    ns = np.round(t * 1e9).astype(np.int64)
    times = [ns[15] / 1e9, ns[15] / 1e9, ns[50] / 1e9, ns[125] / 1e9]
    c = ReplayCursor(t, min_dist(), times)
    assert c.event_index() == 0
    got = []
    while c.next_event():
        got.append((c.frame, c.event_index()))
    assert got == [(15, 2), (50, 3), (125, 4)]  # two at one time: one stop
    assert c.paused
    back = []
    while c.previous_event():
        back.append(c.frame)
    assert back == [50, 15]
    c.step(-1)
    assert c.event_index() == 0 and not c.previous_event()


def test_history_is_the_min_of_each_quarter_second_so_far() -> None:
    t, md = series_t(), min_dist()
    c = ReplayCursor(t, md)
    for k in (0, 1, 12, 13, 74, K - 1):
        c.seek(t[k])
        bins = np.floor(t[: k + 1] / HISTORY_PERIOD_S + 1e-9).astype(int)
        want = [float(md[: k + 1][bins == b].min()) for b in range(bins[-1] + 1)]
        assert c.history() == want


def test_a_series_that_cannot_be_replayed_is_named() -> None:
    assert series_problem(np.zeros(0), np.zeros(0)) is not None
    assert series_problem(np.array([0.0, np.nan]), np.zeros(2)) is not None
    assert "increase" in str(series_problem(np.array([0.0, 0.02, 0.02]), np.zeros(3)))
    assert "shape" in str(series_problem(series_t(), np.zeros(3)))
    assert series_problem(series_t(), min_dist()) is None
    with pytest.raises(ValueError):
        ReplayCursor(np.array([1.0, 0.5]), np.zeros(2))


class Wall:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def make_run() -> ReplayRun:
    sc = load_scenario(CUBE8)
    ids = [int(i) for i in sc.ids]
    n = len(ids)
    rng = np.random.default_rng(7)
    s = empty_series(series_t(), n, math.nan)
    s.p[:] = np.asarray([a.position for a in sc.agents]) + rng.normal(0, 0.3, (K, n, 3))
    s.v[:] = rng.normal(0, 1, (K, n, 3))
    s.p_des[:] = s.p + 0.1
    s.z1[:] = s.p + 0.05
    s.thrust[:] = 15.0
    s.thrust[:10, 3] = 0.0  # vehicle 4 on its pad at first
    s.h_min[:] = 2.0
    s.solve_us[:] = 40.0
    s.min_dist[:] = min_dist()
    s.fallback[60:62, 2] = True  # vehicle 3's QP degrades at 1.2 s, recovers at 1.24 s
    s.alarms[80:, 4] = int(AgentAlarm.FALLBACK)  # vehicle 5 raises an alarm at 1.6 s
    doc = {"scenario": "cube8", "method": "rcbf", "seed": 1,
           "metrics": {"min_distance_m": float(s.min_dist.min()), "safety_verdict": "unsafe",
                       "safety_alarms": [{"assumption": "collision", "agent": 1, "other": 2,
                                          "value": 0.1, "t_s": 1.0}]}}
    return ReplayRun("run (cube8)", ids, doc, s, sc)


def test_the_view_of_a_frame_is_the_series_at_that_frame() -> None:
    run = make_run()
    s = run.series
    src = ReplaySource(run, clock=Wall())
    for k in (0, 5, 61, 90, K - 1):
        src.cursor.seek(s.t[k])
        v = src.view()
        assert v.t == v.sim_time == s.t[k]
        assert v.min_dist == s.min_dist[k] and v.d_safe == run.scenario.controller.d_safe_m
        assert v.collisions == (1 if s.t[k] >= 1.0 else 0)
        for a, r in enumerate(v.rows):
            assert r.id == run.ids[a] and r.pos == tuple(s.p[k, a])
            others = [np.linalg.norm(s.p[k, a] - s.p[k, b]) for b in range(len(run.ids))
                      if b != a]
            assert r.nn_dist == pytest.approx(min(others), abs=1e-12)
            assert r.track_err == pytest.approx(np.linalg.norm(s.p[k, a] - s.p_des[k, a]))
            assert r.est_err == pytest.approx(np.linalg.norm(s.z1[k, a] - s.p[k, a]))
            assert r.armed == (s.thrust[k, a] > 0) and r.mode == VehicleMode.OFFBOARD
        assert v.rows[2].qp_status == ("fallback" if s.fallback[k, 2] else "solved")
        assert v.rows[4].failsafe == ("FALLBACK" if s.alarms[k, 4] else "ok")


def test_events_come_in_order_and_again_after_a_jump_back() -> None:
    run = make_run()
    wall = Wall()
    src = ReplaySource(run, clock=wall)
    texts = [(e.t, e.agent, e.text) for e in src.events]
    assert texts[0][2].startswith("start: scenario cube8")
    assert (pytest.approx(1.2), 3, "QP degraded: fallback") in texts
    assert (pytest.approx(1.24), 3, "QP recovered") in texts
    assert (pytest.approx(1.6), 5, "alarm FALLBACK") in texts
    crash = next(e for e in src.events if e.text.startswith("collision"))
    assert crash.t == 1.0 and crash.severity == mavlink.MAV_SEVERITY_ERROR
    assert [e.t for e in src.events] == sorted(e.t for e in src.events)
    got = []
    for _ in itertools.repeat(None, 40):  # 4 s of wall time at x1, 0.1 s a poll
        _, new = src.poll()
        got += new
        wall.now += 0.1
    assert got == src.events  # each once, the end included
    src.cursor.seek(1.1)
    src.restart_events()
    _, again = src.poll()
    assert again == [e for e in src.events if e.t <= 1.1]
