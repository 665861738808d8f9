"""When the dashboard calls a vehicle's link lost (gcs.dashboard.link_tracker): only on the
heartbeat timeout, on the sim clock, and up to what its reader has read."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as M

from gcs.dashboard.link_tracker import LinkTracker

TIMEOUT = 2.0


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _frames(sysid: int, sim_ms: int) -> bytes:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=M.MAV_COMP_ID_AUTOPILOT1)
    hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, 1, 3 << 16,
                                     M.MAV_STATE_STANDBY, 3).pack(mav)
    att = M.MAVLink_attitude_message(sim_ms, 0, 0, 0, 0, 0, 0).pack(mav)
    return hb + att


def _tracker() -> tuple[LinkTracker, Clock]:
    clk = Clock()
    return LinkTracker(clk, 255, M.MAV_COMP_ID_MISSIONPLANNER), clk


def _lost(tr: LinkTracker) -> set[int]:
    return {i for i, v in tr.vehicles().items() if v.lost}


def test_a_reader_behind_on_its_socket_sees_no_silence() -> None:
    tr, clk = _tracker()
    for k in range(3):  # real time: 1 Hz heartbeats, stamps with the wall
        clk.t = 100.0 + k
        tr.feed(_frames(1, 1000 * k), ("127.0.0.1", 1))
    clk.t = 110.0  # 8 s later the reader is still busy with an older backlog
    tr.update(clk.t, TIMEOUT, caught_up=102.5)
    assert _lost(tr) == set()
    tr.update(clk.t, TIMEOUT, caught_up=110.0)  # it read everything: really silent
    assert _lost(tr) == {1}


def _gap(rate: float) -> set[int]:
    """Both vehicles stream 10 Hz on the wall clock, stamps at ``rate`` x real time;
    vehicle 2's datagrams pause for 3 wall seconds (> the timeout)."""
    tr, clk = _tracker()
    for k in range(60):
        clk.t = 100.0 + 0.1 * k
        sim_ms = int(1000 * rate * 0.1 * k)
        tr.feed(_frames(1, sim_ms), ("127.0.0.1", 1))
        if not 10 <= k < 40:
            tr.feed(_frames(2, sim_ms), ("127.0.0.1", 2))
        tr.update(clk.t, TIMEOUT, caught_up=clk.t)
        if k == 39:
            lost = _lost(tr)
    return lost


def test_a_lockstep_run_slower_than_the_wall_is_judged_on_the_sim_clock() -> None:
    assert _gap(rate=1.0) == {2}  # real time: 3 s without its heartbeat
    assert _gap(rate=0.25) == set()  # 0.25x: the sim clock moved on 0.75 s only


def test_a_vehicle_silent_while_the_sim_clock_moves_on_is_lost() -> None:
    tr, clk = _tracker()
    for k in range(6):
        clk.t = 100.0 + k
        tr.feed(_frames(1, 1000 * k), ("127.0.0.1", 1))
        if k < 2:
            tr.feed(_frames(2, 1000 * k), ("127.0.0.1", 2))  # vehicle 2 stops after 1 s
        tr.update(clk.t, TIMEOUT, caught_up=clk.t)
    assert _lost(tr) == {2}
    ev = [e for e in tr.drain_events() if e.kind == "link"]
    assert [e.sysid for e in ev] == [2] and ev[0].severity == M.MAV_SEVERITY_CRITICAL
    clk.t = 106.0
    tr.feed(_frames(2, 6000), ("127.0.0.1", 2))  # back: regained, once
    assert _lost(tr) == set()
    assert [e.text for e in tr.drain_events() if e.kind == "link"] == ["link regained"]


def test_everything_silent_is_lost_on_the_wall_clock() -> None:
    tr, clk = _tracker()
    clk.t = 100.0
    tr.feed(_frames(1, 5000), ("127.0.0.1", 1))
    tr.feed(_frames(2, 5000), ("127.0.0.1", 2))
    tr.update(101.9, TIMEOUT, caught_up=101.9)
    assert _lost(tr) == set()
    tr.update(102.5, TIMEOUT, caught_up=102.5)  # the simulator is gone: nothing arrives
    assert _lost(tr) == {1, 2}
