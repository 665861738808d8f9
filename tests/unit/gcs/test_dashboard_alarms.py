"""The dashboard's view of the agents' safety alarm bits (docs/safety.md, "In-flight alarms
and the fallback"): an event at each onset, named, and the row's failsafe cell."""

from __future__ import annotations

from types import SimpleNamespace

from pymavlink.dialects.v20 import common as mavlink

from gcs.dashboard.state import VehicleRow, failsafe_label
from gcs.dashboard.zenoh_feed import FeedEvent, ZenohFeed
from swarm_common.enums import AgentAlarm
from swarm_common.wire import Status


def _status(alarms: int) -> Status:
    return Status(3, 1, 0.02, "OFFBOARD", "dcbf", "solved", 5.0, 1.0, 0.1, "ok", 0,
                  alarms=alarms)


def _events(prev: int, now: int) -> list[FeedEvent]:
    feed = SimpleNamespace(_events=[])
    ZenohFeed._status_events(feed, _status(prev), _status(now), 1.0)  # type: ignore[arg-type]
    return [e for e in feed._events if e.kind == "safety"]


def test_alarm_onsets_make_named_events() -> None:
    assert _events(0, 0) == [] and _events(1, 1) == [] and _events(5, 1) == []
    (e,) = _events(0, int(AgentAlarm.RESIDUAL))
    assert "RESIDUAL" in e.text and e.severity == mavlink.MAV_SEVERITY_ERROR and e.agent == 3
    (f,) = _events(int(AgentAlarm.RESIDUAL), int(AgentAlarm.RESIDUAL | AgentAlarm.FALLBACK))
    assert "FALLBACK" in f.text and "RESIDUAL" not in f.text
    assert f.severity == mavlink.MAV_SEVERITY_CRITICAL


def test_row_shows_the_alarm() -> None:
    row = VehicleRow(3, "follower", link_lost=False)
    row.status_missing = False
    assert failsafe_label(row, True, "ok", False) == "ok"
    assert failsafe_label(row, True, "ok", False, int(AgentAlarm.NEAR_ENTRY)) == "ALARM"
    assert failsafe_label(row, True, "ok", False, 5) == "FALLBACK"
