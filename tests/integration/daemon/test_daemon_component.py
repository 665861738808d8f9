"""The offboard daemon as a MAVLink component (docs/px4/offboard-component.md): a real
``vehicle-sim`` with one vehicle (agent 1 of cube8), one ``offboard`` daemon and a Zenoh
router hosted by the test, over 127.0.0.1.

* The daemon's ``.tlog`` (what it sent, as sent) holds its own HEARTBEATs as component 191
  (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID) and pymavlink's loss count
  (``mavloss``: sequence-number gaps per sender) is 0 for that component.
* Alone with its vehicle and no neighbours the daemon does not arm (the vehicle's
  HEARTBEAT on the GCS link stays disarmed) and its log says why; with ``--solo`` it arms.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from conftest import CUBE8, ROOT, FollowedChild, MavClient  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from gcs.mission.procs import python_entry  # noqa: E402
from swarm_common import px4  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.zenoh_session import default_endpoint, open_session  # noqa: E402

pytestmark = pytest.mark.timeout(120)

M = mavutil.mavlink
GROUND8 = ROOT / "scenarios" / "ground8.toml"
ONBOARD = (1, M.MAV_COMP_ID_ONBOARD_COMPUTER)


class Daemon(FollowedChild):
    """``offboard --agent 1`` as a child process (forked as a run forks it), its log
    followed."""

    def __init__(self, off: int, tlog: Path, extra: list[str], scenario: Path = CUBE8) -> None:
        super().__init__(
            [*python_entry("offboard.cli"), "--scenario", str(scenario), "--agent", "1",
             "--port-offset", str(off), "--realtime", "--sensing", "odometry",
             "--zenoh-connect", default_endpoint(off), "--tlog", str(tlog), *extra],
            prefix="offboard-1-",
        )

    def wait_for(self, text: str, timeout: float) -> bool:
        return self.wait_log(re.escape(text), timeout) is not None

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 15.0) -> str:  # type: ignore[override]
        """Stop it (SIGTERM, then SIGKILL after ``timeout``); its whole log."""
        super().stop(sig, timeout)
        return self.text()


@pytest.fixture
def one_vehicle(sim_factory) -> Iterator[tuple[int, MavClient]]:
    """(port offset, a GCS listening on vehicle 1's GCS link): ``vehicle-sim --vehicles 1``
    (real time, no truth) and a Zenoh router on the offset's endpoint."""
    yield from _one_vehicle(sim_factory, CUBE8)


@pytest.fixture
def one_vehicle_on_the_ground(sim_factory) -> Iterator[tuple[int, MavClient]]:
    """:func:`one_vehicle` of ground8 (on its pad)."""
    yield from _one_vehicle(sim_factory, GROUND8)


def _one_vehicle(sim_factory, scenario: Path) -> Iterator[tuple[int, MavClient]]:
    sim = sim_factory(["--vehicles", "1", "--no-zenoh"], scenario=str(scenario))
    off = sim.offset
    router = open_session(mode="router", listen=[default_endpoint(off)])
    gcs = MavClient(vehicle_ports(1, off).gcs_remote)
    try:
        yield off, gcs
    finally:
        gcs.close()
        router.close()


def _vehicle_armed(gcs: MavClient) -> bool | None:
    hb = gcs.recv("HEARTBEAT", timeout=5.0, sysid=1,
                  cond=lambda m: m.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1)
    return None if hb is None else bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def _sent_by_daemon(tlog: Path) -> list[object]:
    """Every message of component (1, 191) in the tlog, in order."""
    mlog = mavutil.mavlink_connection(str(tlog))
    out = []
    while (m := mlog.recv_match()) is not None:
        if (m.get_srcSystem(), m.get_srcComponent()) == ONBOARD:
            out.append(m)
    return out


def _mavloss(msgs: list[object]) -> tuple[int, int]:
    """(received, lost) by pymavlink mavloss's rule: a gap in the 8-bit sequence."""
    lost = 0
    last: int | None = None
    for m in msgs:
        seq = m.get_seq()  # type: ignore[attr-defined]
        if last is not None:
            lost += (seq - last - 1) % 256
        last = seq
    return len(msgs), lost


def test_alone_it_waits_and_does_not_arm(one_vehicle, tmp_path: Path) -> None:
    off, gcs = one_vehicle
    tlog = tmp_path / "vehicle_1.tlog"
    d = Daemon(off, tlog, [])
    try:
        assert d.wait_for("vehicle link udpin:127.0.0.1:", 30), d.lines
        assert d.wait_for("waiting for its swarm, not arming", 40), d.lines
        said = sum("waiting for its swarm" in ln for ln in d.lines)
        assert d.wait_for("missing [2, 3, 4, 5, 6, 7, 8]", 1)
        time.sleep(4.0)
        gcs.drain()
        assert _vehicle_armed(gcs) is False
        assert sum("waiting for its swarm" in ln for ln in d.lines) > said  # repeated
        assert not any("ARM accepted" in ln for ln in d.lines)
    finally:
        text = d.stop()
    print(text)
    msgs = _sent_by_daemon(tlog)
    beats = [m for m in msgs if m.get_type() == "HEARTBEAT"]
    assert len(beats) >= 2
    assert all(m.type == M.MAV_TYPE_ONBOARD_CONTROLLER  # type: ignore[attr-defined]
               and m.autopilot == M.MAV_AUTOPILOT_INVALID for m in beats)  # type: ignore[attr-defined]
    assert not any(m.get_type() == "SET_ATTITUDE_TARGET" for m in msgs)


def test_solo_arms_and_loses_no_sequence_number(one_vehicle, tmp_path: Path) -> None:
    off, gcs = one_vehicle
    tlog = tmp_path / "vehicle_1.tlog"
    d = Daemon(off, tlog, ["--solo"])
    try:
        assert d.wait_for("ARM accepted", 60), d.lines
        deadline = time.monotonic() + 10
        armed = False
        while not armed and time.monotonic() < deadline:
            armed = bool(_vehicle_armed(gcs))
        assert armed
        time.sleep(4.0)  # a few more seconds of setpoints and heartbeats (seq wraps at 256)
    finally:
        text = d.stop()
    print(text)
    keep = os.environ.get("KEEP_TLOG")  # developer aid: keep the tlog for mavloss
    if keep:
        Path(keep).write_bytes(tlog.read_bytes())
    msgs = _sent_by_daemon(tlog)
    received, lost = _mavloss(msgs)
    assert received > 0
    assert lost == 0
    # and pymavlink's own tool, one row per (sysid, compid): "1  191  packets  lost  0.0%"
    tool = subprocess.run([sys.executable, "-m", "pymavlink.tools.mavloss", str(tlog)],
                          capture_output=True, text=True, timeout=60, check=True)
    rows = [ln.split() for ln in tool.stdout.splitlines()]
    ours = [r for r in rows if r[:2] == ["1", str(M.MAV_COMP_ID_ONBOARD_COMPUTER)]]
    assert len(ours) == 1 and ours[0][3:] == ["0", "0.0%"], tool.stdout
    kinds = {m.get_type() for m in msgs}
    assert {"HEARTBEAT", "SET_ATTITUDE_TARGET", "COMMAND_LONG"} <= kinds
    assert sum(m.get_type() == "HEARTBEAT" for m in msgs) >= 2


def _mode(gcs: MavClient) -> tuple[int, int, bool] | None:
    """(main mode, sub mode, armed) of vehicle 1's next HEARTBEAT on the GCS link."""
    hb = gcs.recv("HEARTBEAT", timeout=5.0, sysid=1,
                  cond=lambda m: m.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1)
    if hb is None:
        return None
    main, sub = px4.split_mode(int(hb.custom_mode))
    return main, sub, bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def test_stopped_right_after_a_ground_stations_offboard_it_takes_the_vehicle_back(
    one_vehicle_on_the_ground, tmp_path: Path
) -> None:
    """``--manual-start``: the ground station puts the vehicle in OFFBOARD; the daemon's
    process is stopped (SIGSTOP) as the ACK comes back, before the vehicle's 1 Hz HEARTBEAT
    can show it OFFBOARD, and the ground station arms it. The offboard-loss failsafe puts
    it in HOLD; resumed 2 s later, the daemon reads the vehicle's "failsafe: offboard
    lost" and asks for OFFBOARD again (offboard.daemon.mavlink.offboard_keeper: it once waited
    forever,
    having never seen OFFBOARD itself)."""
    off, gcs = one_vehicle_on_the_ground
    d = Daemon(off, tmp_path / "vehicle_1.tlog", ["--solo", "--manual-start"], GROUND8)
    try:
        assert d.wait_for("on its pad until the take-off command", 60), d.lines
        time.sleep(1.5)  # its setpoints stream: the vehicle accepts OFFBOARD
        assert _mode(gcs) is not None  # the client knows where the vehicle is
        gcs.drain()
        ack = gcs.command(1, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                          px4.MAIN_OFFBOARD, timeout=10.0)
        os.kill(d.proc.pid, signal.SIGSTOP)
        try:
            assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED, ack
            ack = gcs.command(1, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=10.0)
            assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED, ack
            time.sleep(2.0)
            gcs.drain()
            hold = (px4.MAIN_AUTO, px4.SUB_AUTO_LOITER, True)
            assert _mode(gcs) == hold  # the failsafe did trip
        finally:
            os.kill(d.proc.pid, signal.SIGCONT)
        assert d.wait_for("back in OFFBOARD after a failsafe", 20), d.lines
        gcs.drain()
        state = _mode(gcs)
        assert state is not None and state[0] == px4.MAIN_OFFBOARD and state[2]
    finally:
        print(d.stop())
