"""The safety verdict (gcs.report.verdict): timed onsets of every broken assumption, the
run's one word and ``gcs mission run``'s exit status."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.exit_codes import EXIT_OK, EXIT_SAFETY
from gcs.report.verdict import (
    ALARM_LIST_MAX,
    Verdict,
    onsets,
    safety_events,
    safety_exit_status,
    summary_line,
    verdict,
    verdict_metrics,
)
from swarm_common.enums import AgentAlarm

DT = 0.02
TAU, D, R_COLL = 0.5, 0.5, 0.15
IDS = [7, 8, 9]


def still(k: int, gaps: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three agents at rest on the x axis at 5 m altitude: agent 8 at x = 0, agent 7 at
    x = −10, agent 9 at x = gaps[k] (m) at step k. (t, p, v)."""
    t = DT * np.arange(k)
    p = np.zeros((k, 3, 3))
    p[:, :, 2] = 5.0
    p[:, 0, 0] = -10.0
    p[:, 2, 0] = gaps
    return t, p, np.zeros_like(p)


def quiet(k: int) -> tuple[np.ndarray, np.ndarray]:
    """(own_h, alarms): every agent's own barrier comfortable, no alarm bit."""
    return np.full((k, 3), 3.0), np.zeros((k, 3), np.uint8)


def test_onsets_are_the_rising_edges_only() -> None:
    c = np.array([[0, 1], [1, 1], [1, 0], [0, 0], [1, 1]], bool)
    k, m = onsets(c)
    assert list(zip(k.tolist(), m.tolist(), strict=True)) == [(0, 1), (1, 0), (4, 0), (4, 1)]


def test_a_pair_inside_d_twice_is_two_barrier_onsets_named_by_ids() -> None:
    gaps = [2.0] * 5 + [0.4] * 2 + [2.0] * 2 + [0.4] * 3  # h = 0.16 − 0.25 < 0 when 0.4 m
    t, p, v = still(len(gaps), gaps)
    own, al = quiet(len(gaps))
    ev = safety_events(t, p, v, np.full(len(gaps), 0.4), own, al, IDS, TAU, D, R_COLL)
    assert [(e["assumption"], e["agent"], e["other"]) for e in ev] == [("barrier", 8, 9)] * 2
    assert [e["t_s"] for e in ev] == pytest.approx([5 * DT, 9 * DT])
    assert ev[0]["value"] == pytest.approx(0.4**2 - D**2)
    assert verdict(ev) is Verdict.UNSAFE


def test_closing_fast_breaks_the_barrier_before_the_distance() -> None:
    """1.2 m apart (h = 1.44 − 0.25 > 0 at rest) but closing at 2 m/s: h = 1.44 − 2·0.5·2·1.2
    − 0.25 = −1.21 < 0 while the distance is still well above D."""
    t, p, v = still(3, [1.2, 1.2, 1.2])
    v[1:, 2, 0] = -2.0
    own, al = quiet(3)
    ev = safety_events(t, p, v, np.full(3, 1.2), own, al, IDS, TAU, D, R_COLL)
    assert [(e["assumption"], e["t_s"]) for e in ev] == [("barrier", pytest.approx(DT))]


def test_a_contact_seen_between_control_steps_counts() -> None:
    """The control samples stay 2 m apart; the physics-rate minimum after step 3 dips under
    the collision radius: one collision, named by the closest pair at that step."""
    t, p, v = still(6, [2.0] * 6)
    min_dist = np.array([2.0, 2.0, 2.0, 0.1, 2.0, 2.0])
    own, al = quiet(6)
    ev = safety_events(t, p, v, min_dist, own, al, IDS, TAU, D, R_COLL)
    assert [(e["assumption"], e["agent"], e["other"], e["t_s"]) for e in ev] == [
        ("collision", 8, 9, pytest.approx(3 * DT))]


def test_a_fast_touchdown_is_a_ground_strike_a_slow_one_is_not() -> None:
    t, p, v = still(4, [2.0] * 4)
    p[:, 0, 2] = [1.0, 0.05, 0.0, 0.0]  # agent 7 falls at 3 m/s
    v[:2, 0, 2] = -3.0
    p[:, 1, 2] = [0.05, 0.03, 0.01, 0.0]  # agent 8 lands at 0.4 m/s
    v[:3, 1, 2] = -0.4
    own, al = quiet(4)
    ev = safety_events(t, p, v, np.full(4, 2.0), own, al, IDS, TAU, D, R_COLL)
    assert [(e["assumption"], e["agent"], e["t_s"]) for e in ev] == [
        ("ground_strike", 7, pytest.approx(2 * DT))]


def test_own_barrier_and_alarm_bits_are_alarms_not_unsafe() -> None:
    t, p, v = still(5, [2.0] * 5)
    own, al = quiet(5)
    own[:, 0] = np.inf  # a leader computes no barrier
    own[2:, 1] = -0.3  # agent 8's margin is used up from step 2
    own[3, 2] = np.nan  # no status that step: not an event
    al[1:, 2] = AgentAlarm.RESIDUAL
    al[4, 2] = AgentAlarm.RESIDUAL | AgentAlarm.FALLBACK
    ev = safety_events(t, p, v, np.full(5, 2.0), own, al, IDS, TAU, D, R_COLL)
    assert [(e["assumption"], e["agent"], e["t_s"]) for e in ev] == [
        ("residual", 9, pytest.approx(DT)), ("own_barrier", 8, pytest.approx(2 * DT)),
        ("fallback", 9, pytest.approx(4 * DT))]
    assert verdict(ev) is Verdict.ALARM
    m = verdict_metrics(t, p, v, np.full(5, 2.0), own, al, IDS, [1, 2], TAU, D, R_COLL)
    assert m["own_h_min"] == pytest.approx(-0.3)
    assert m["safety_verdict"] == "alarm" and m["safety_alarm_count"] == 3


def test_a_fence_the_filter_could_not_take_is_an_alarm() -> None:
    t, p, v = still(5, [2.0] * 5)
    own, al = quiet(5)
    al[2:, 1] = AgentAlarm.FENCE_MISMATCH  # held from step 2: one event at its onset
    m = verdict_metrics(t, p, v, np.full(5, 2.0), own, al, IDS, [1, 2], TAU, D, R_COLL)
    assert [(e["assumption"], e["agent"]) for e in m["safety_alarms"]] == [("fence_mismatch", 8)]
    assert m["safety_verdict"] == "alarm" and safety_exit_status(m, "dcbf") == EXIT_SAFETY


def test_a_quiet_run_is_safe_and_exits_0() -> None:
    t, p, v = still(5, [2.0] * 5)
    own, al = quiet(5)
    m = verdict_metrics(t, p, v, np.full(5, 2.0), own, al, IDS, [1, 2], TAU, D, R_COLL)
    assert m == {"own_h_min": 3.0, "safety_verdict": "safe", "safety_alarm_count": 0,
                 "deadlock_events": 0, "safety_alarms": []}
    assert summary_line(m) is None
    assert safety_exit_status(m, "dcbf") == EXIT_OK


def test_exit_status_is_3_for_a_filter_only() -> None:
    m = {"safety_verdict": "unsafe", "safety_alarm_count": 1, "safety_alarms": [
        {"t_s": 0.8, "assumption": "collision", "agent": 3, "other": 4, "value": 0.1}]}
    assert safety_exit_status(m, "dcbf") == safety_exit_status(m, "rcbf") == EXIT_SAFETY
    assert safety_exit_status(m, "none") == safety_exit_status(m, "apf") == EXIT_OK
    assert safety_exit_status({**m, "safety_verdict": "alarm"}, "dcbf") == EXIT_SAFETY
    line = summary_line(m)
    assert line is not None and "UNSAFE" in line and "collision of 3-4 at t=0.80 s" in line


def test_the_list_is_capped_the_count_is_not() -> None:
    k = 2 * ALARM_LIST_MAX + 10
    t, p, v = still(k, [2.0] * k)
    own, al = quiet(k)
    al[1::2, 1] = AgentAlarm.NEAR_ENTRY  # on, off, on, ...: an onset every other step
    m = verdict_metrics(t, p, v, np.full(k, 2.0), own, al, IDS, [1, 2], TAU, D, R_COLL)
    assert m["safety_alarm_count"] == ALARM_LIST_MAX + 5
    assert len(m["safety_alarms"]) == ALARM_LIST_MAX
    assert m["safety_alarms"][0]["t_s"] == pytest.approx(DT)  # the earliest kept


def test_a_deadlock_is_listed_but_leaves_the_run_safe() -> None:
    t, p, v = still(4, [2.0] * 4)
    own, al = quiet(4)
    al[2:, 2] = AgentAlarm.DEADLOCK
    m = verdict_metrics(t, p, v, np.full(4, 2.0), own, al, IDS, [1, 2], TAU, D, R_COLL)
    assert [(e["assumption"], e["agent"]) for e in m["safety_alarms"]] == [("deadlock", 9)]
    assert m["deadlock_events"] == 1
    assert m["safety_verdict"] == "safe" and safety_exit_status(m, "dcbf") == EXIT_OK
