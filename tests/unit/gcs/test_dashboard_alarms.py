"""The dashboard's view of the agents' safety alarm bits (docs/safety.md, "In-flight alarms
and the fallback"): an event at each onset, named, and the row's failsafe cell."""

from __future__ import annotations

from types import SimpleNamespace

from pymavlink.dialects.v20 import common as mavlink

from gcs.dashboard.view.state import VehicleRow, failsafe_label
from gcs.dashboard.zenoh_feed import FeedEvent, ZenohFeed
from swarm_common.enums import AgentAlarm
from swarm_common.wire import Status


def _status(alarms: int, mode: str = "OFFBOARD", est_health: str = "ok", fallbacks: int = 0,
            qp_status: str = "solved", comm_ok: bool = True) -> Status:
    return Status(3, 1, 0.02, mode, "dcbf", qp_status, 5.0, 1.0, 0.1, est_health, fallbacks,
                  comm_ok=comm_ok, alarms=alarms)


def _all_events(prev: Status, now: Status) -> list[FeedEvent]:
    feed = SimpleNamespace(_events=[])
    ZenohFeed._status_events(feed, prev, now, 1.0)  # type: ignore[arg-type]
    return list(feed._events)


def _events(prev: int, now: int) -> list[FeedEvent]:
    return [e for e in _all_events(_status(prev), _status(now)) if e.kind == "safety"]


def test_alarm_onsets_make_named_events() -> None:
    assert _events(0, 0) == [] and _events(1, 1) == [] and _events(5, 1) == []
    (e,) = _events(0, int(AgentAlarm.RESIDUAL))
    assert "RESIDUAL" in e.text and e.severity == mavlink.MAV_SEVERITY_ERROR and e.agent == 3
    (f,) = _events(int(AgentAlarm.RESIDUAL), int(AgentAlarm.RESIDUAL | AgentAlarm.FALLBACK))
    assert "FALLBACK" in f.text and "RESIDUAL" not in f.text
    assert f.severity == mavlink.MAV_SEVERITY_CRITICAL


def test_nothing_is_an_error_before_the_agent_flies_its_vehicle() -> None:
    """On the pads (POSCTL): QP fallbacks are not reported, a comm outage and a degraded
    estimator are states (INFO); entering OFFBOARD reports what is still wrong, as errors."""
    calm = _status(0, "POSCTL")
    bad = _status(int(AgentAlarm.RESIDUAL), "POSCTL", comm_ok=False, est_health="predicting",
                  fallbacks=7, qp_status="relaxed")
    pre = _all_events(calm, bad)
    assert {e.kind for e in pre} == {"comm", "estimator"}
    assert all(e.severity == mavlink.MAV_SEVERITY_INFO for e in pre)
    flying = _status(int(AgentAlarm.RESIDUAL), comm_ok=False, est_health="predicting",
                     fallbacks=8, qp_status="relaxed")
    entry = {e.kind: e for e in _all_events(bad, flying)}
    assert {"comm", "estimator", "safety", "fallback", "mode"} <= set(entry)
    for kind in ("comm", "estimator", "safety"):
        assert entry[kind].severity <= mavlink.MAV_SEVERITY_ERROR, kind
    assert "RESIDUAL" in entry["safety"].text


def test_row_shows_the_alarm() -> None:
    row = VehicleRow(3, "follower", link_lost=False, mode="OFFBOARD")
    row.status_missing = False
    assert failsafe_label(row, True, "ok", False) == "ok"
    assert failsafe_label(row, True, "ok", False, int(AgentAlarm.NEAR_ENTRY)) == "ALARM"
    assert failsafe_label(row, True, "ok", False, 5) == "FALLBACK"
    assert failsafe_label(row, True, "predicting", False) == "EST:predi"[:8]
    row.mode = "POSCTL"  # on the pads: the agent's alarms and estimator are no failsafe yet
    assert failsafe_label(row, True, "predicting", False, 5) == "ok"
    row.link_lost = True
    assert failsafe_label(row, True, "ok", False) == "LINK"
