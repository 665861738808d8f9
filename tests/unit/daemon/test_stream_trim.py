"""offboard.daemon.mavlink.stream_trim: which vehicle messages retrigger the stop-streams request,
and
its rate limit."""

from __future__ import annotations

from offboard.daemon.mavlink.stream_trim import RETRY_S, StreamTrim, stop_streams_message


def test_group_telemetry_retriggers_at_most_once_per_period() -> None:
    trim = StreamTrim()
    assert trim.due(0.0)  # the first request, at lock
    assert not trim.on_message("ATTITUDE", 0.1)  # within RETRY_S of it
    assert trim.on_message("ATTITUDE", RETRY_S + 0.01)  # still streaming: ask again
    assert not trim.on_message("VFR_HUD", RETRY_S + 0.02)
    assert trim.requests == 2 and trim.unread == 3


def test_read_and_ungrouped_messages_never_retrigger() -> None:
    trim = StreamTrim()
    for t, kind in enumerate(("HEARTBEAT", "ODOMETRY", "COMMAND_ACK", "STATUSTEXT",
                              "DATA_STREAM", "MISSION_CURRENT")):
        assert not trim.on_message(kind, 10.0 * t)
    assert trim.requests == 0


def test_disabled_never_asks() -> None:
    trim = StreamTrim(enabled=False)
    assert not trim.due(0.0)
    assert not trim.on_message("ATTITUDE", 100.0)


def test_request_is_stop_all_to_the_autopilot() -> None:
    msg = stop_streams_message(7)
    assert (msg.target_system, msg.target_component) == (7, 1)
    assert (msg.req_stream_id, msg.req_message_rate, msg.start_stop) == (0, 0, 0)
