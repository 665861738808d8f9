"""The event log's timeline (gcs.dashboard.view.timeline): one sim clock, repeats merged."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from gcs.dashboard.view.state import DashEvent
from gcs.dashboard.view.timeline import (
    MAX_EXTRAPOLATION_S,
    REPEAT_WINDOW_S,
    EventMerger,
    SimClock,
)

WARN, ERR, INFO = (mavlink.MAV_SEVERITY_WARNING, mavlink.MAV_SEVERITY_ERROR,
                   mavlink.MAV_SEVERITY_INFO)


def test_sim_clock_reads_sim_time_at_a_wall_instant() -> None:
    c = SimClock()
    assert math.isnan(c.at(5.0)) and not c.known
    c.observe(12.0, 100.0)  # sim 12 s heard at wall 100 s
    assert c.at(100.25) == 12.25 and c.at(99.5) == 11.5
    # a sim that stopped (or a slow lockstep run) is not carried on for ever
    assert c.at(160.0) == 12.0 + MAX_EXTRAPOLATION_S
    c.observe(11.9, 100.5)  # a late packet: ignored
    assert c.at(100.5) == 12.5
    c.observe(13.0, 100.6)  # a newer stamp moves the reference
    assert abs(c.at(100.7) - 13.1) < 1e-12
    c.observe(0.5, 101.0)  # far older: the simulator started again
    assert c.at(101.0) == 0.5
    c.observe(float("nan"), 102.0)
    assert c.at(101.0) == 0.5


def _ev(text: str, t: float = 1.0, agent: int = 3, sev: int = WARN) -> DashEvent:
    return DashEvent(t, agent, "fallback", text, sev)


def test_a_flood_is_one_line_per_window_with_its_count() -> None:
    m: EventMerger[DashEvent] = EventMerger()
    shown: list[DashEvent] = []
    wall = 0.0
    for k in range(1, 401):  # 16 Hz for 25 s (1/16 s is exact in binary)
        wall = k / 16
        shown += m.push([_ev(f"QP fallback (relaxed), total {k}", t=wall)], wall)
    first, *repeats = shown
    assert first.text == "QP fallback (relaxed), total 1"
    assert len(repeats) == 2  # windows closed at 10.06 s and 20.06 s
    assert repeats[0].text == "QP fallback (relaxed), total 161 (again 160x in 10 s)"
    tail = m.flush(wall, force=True)
    counted = sum(int(r.text.split("again ")[1].split("x")[0]) for r in repeats + tail)
    assert 1 + counted == 400 and m.merged == 399  # every event counted once, none lost


def test_different_events_are_not_merged_and_severity_is_the_worst() -> None:
    m: EventMerger[DashEvent] = EventMerger()
    out = m.push([_ev("comm outage", agent=3), _ev("comm outage", agent=4),
                  _ev("estimator predicting", agent=3)], 0.0)
    assert len(out) == 3
    assert m.push([_ev("comm outage", agent=3, sev=INFO), _ev("comm outage", agent=3, sev=ERR)],
                  1.0) == []
    (line,) = m.push([], REPEAT_WINDOW_S + 0.1)[:1]
    assert line.agent == 3 and "again 2x" in line.text and line.severity == ERR
    # once quiet for a whole window, the next occurrence is shown in full again
    assert m.push([], 3 * REPEAT_WINDOW_S) == []
    again = m.push([_ev("comm outage", agent=3)], 3 * REPEAT_WINDOW_S + 1)
    assert [e.text for e in again] == ["comm outage"]
