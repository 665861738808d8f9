"""The offboard daemon under attack and faults (docs/security.md, "Offboard daemon: link
hygiene and failsafes"): real ``vehicle-sim``, eight ``offboard`` daemons and the runner's
Zenoh router over 127.0.0.1, shortened cube8 missions. Each test asserts safety (no
collision, minimum distance >= 0.5 m, no fly-away) and what the daemons detected.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from conftest import CUBE8, free_port_offset, free_tcp_port, start_child  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from gcs.mission.distributed import recorded_metrics, run_distributed  # noqa: E402
from gcs.mission.procs import ChildProcess, python_entry  # noqa: E402
from swarm_common import wire  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.scenario.model import Scenario, load_scenario  # noqa: E402
from swarm_common.signing import generate_key  # noqa: E402
from swarm_common.zenoh_session import default_endpoint, open_session  # noqa: E402

pytestmark = pytest.mark.timeout(180)

FORGED_STAMP = 2**62
FLOOD = 3000
CAPTURE_SOCKETS = 16  # flood senders kept open to see whether the daemon answers them
ARENA_M = 25.0  # cube8 flies within ~10 m of the origin; a fly-away leaves this
MIN_DIST_M = 0.5


def _wait_text(path: Path, text: str, timeout: float, stop: threading.Event) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not stop.is_set():
        if path.exists() and text in path.read_text(errors="replace"):
            return True
        time.sleep(0.1)
    return False


class Attack(threading.Thread):
    """Runs ``action`` once daemon ``agent`` has armed its vehicle (its log says so)."""

    def __init__(self, log: Path, action: Callable[[], None]) -> None:
        super().__init__(daemon=True)
        self.log, self.action = log, action
        self.halt = threading.Event()
        self.done = False
        self.error: BaseException | None = None

    def run(self) -> None:
        if not _wait_text(self.log, "ARM accepted", 120.0, self.halt):
            return
        try:
            self.action()
            self.done = True
        except BaseException as exc:  # reported by the test's assertion
            self.error = exc


def _run_under_attack(tmp: Path, sc: Scenario, log: Path, action: Callable[[], None],
                      dur: float, off: int, realtime: bool) -> tuple[Any, dict]:
    """A distributed dcbf run with ``action`` launched once ``log`` says the daemon armed;
    asserts the attack ran to its end without error. dcbf, the default method, because
    its barrier is what keeps the 0.5 m these tests assert (docs/safety.md): rcbf, the
    paper's, does not guarantee it, and beside a stopped daemon came to 0.49 m once on a
    loaded CI host (docs/security.md, "Tests")."""
    attacker = Attack(log, action)
    attacker.start()
    try:
        rec, facts = run_distributed(sc, tmp, "dcbf", None, dur, realtime=realtime,
                                     port_offset=off, show_progress=False, secure=False)
    finally:
        attacker.halt.set()
        attacker.join(10)
    assert attacker.error is None and attacker.done
    return rec, facts


MODE_LINE = re.compile(r"vehicle (\d+): mode (\S+) -> (\S+)")


def _modes(tmp: Path) -> dict[int, list[str]]:
    """Every vehicle's mode changes, from the simulator's log."""
    out: dict[int, list[str]] = {}
    for m in MODE_LINE.finditer((tmp / "vehicle-sim.log").read_text(errors="replace")):
        out.setdefault(int(m.group(1)), []).append(m.group(3))
    return out


def _safe_and_normal(tmp: Path, sc: Scenario, rec: Any, facts: dict, dur: float) -> None:
    """No collision, minimum distance >= 0.5 m, nobody left the arena, every vehicle
    in OFFBOARD at the end, no daemon died."""
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], dur)
    assert m["collisions"] == 0
    assert m["min_distance_m"] >= MIN_DIST_M
    assert float(np.max(np.linalg.norm(ser.p, axis=2))) < ARENA_M
    modes = _modes(tmp)
    assert all(modes.get(i, ["?"])[-1] == "OFFBOARD" for i in sc.ids), modes
    assert facts["failed_agents"] == []


def _forged_odometry(victim: int) -> bytes:
    mav = mavlink.MAVLink(None, victim, mavlink.MAV_COMP_ID_AUTOPILOT1)
    msg = mavlink.MAVLink_odometry_message(
        FORGED_STAMP, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD,
        0.0, 0.0, -100.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        [float("nan")] * 21, [float("nan")] * 21,
    )
    return bytes(msg.pack(mav))


def test_forged_odometry_and_sender_flood_change_nothing(tmp_path: Path) -> None:
    """Forged ODOMETRY (time_usec 2^62, the victim's system id) to daemon 3's port, and
    3000 one-byte datagrams from 3000 source ports to daemon 5's port, during a lockstep
    run: both are dropped and counted; the flood's senders receive nothing (setpoints go
    to the locked vehicle address only); the swarm flies on normally."""
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    dur = 8.0
    got_back: list[int] = []

    def attack() -> None:
        forged = _forged_odometry(3)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for _ in range(5):
                s.sendto(forged, ("127.0.0.1", vehicle_ports(3, off).api_remote))
                time.sleep(0.05)
        target = ("127.0.0.1", vehicle_ports(5, off).api_remote)
        kept: list[socket.socket] = []
        for i in range(FLOOD):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.sendto(b"\x00", target)
            if i >= FLOOD - CAPTURE_SOCKETS:
                s.setblocking(False)
                kept.append(s)
            else:
                s.close()
        time.sleep(1.5)  # many control steps: old daemons sent every setpoint to each
        for s in kept:
            try:
                got_back.append(len(s.recv(65535)))
            except BlockingIOError:
                pass
            s.close()

    rec, facts = _run_under_attack(tmp_path, sc, tmp_path / "offboard-5.log", attack, dur, off,
                                   realtime=False)
    assert got_back == []  # not one datagram to a stranger
    _safe_and_normal(tmp_path, sc, rec, facts, dur)
    log3 = (tmp_path / "offboard-3.log").read_text()
    log5 = (tmp_path / "offboard-5.log").read_text()
    assert "link locked" in log3 and "dropped" in log3 and "foreign address" in log3
    assert "dropped" in log5 and "foreign address" in log5


def test_fake_truth_and_estimates_over_zenoh_are_ignored(tmp_path: Path) -> None:
    """A Zenoh client publishes a Truth with step 2^40 and estimates with a huge step
    (every agent's id) during a real-time run: every daemon drops and counts them; no
    truth freezes, no store is wiped, the swarm flies on."""
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    dur = 10.0
    n = len(sc.ids)

    def attack() -> None:
        sess = open_session(mode="client", connect=[default_endpoint(off)])
        try:
            big = 2**40
            truth = wire.Truth(step=big, t=big / sc.run.control_hz, ids=list(sc.ids),
                               p=np.zeros((n, 3)), v=np.zeros((n, 3)), att=np.zeros((n, 3)),
                               thrust=np.zeros(n), lumped=np.zeros((n, 3)), armed=[True] * n,
                               mode=["OFFBOARD"] * n, collisions=0)
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline:
                sess.put(wire.key_truth(sc.name), wire.encode(truth))
                for aid in sc.ids:
                    est = wire.Estimate(
                        id=aid, step=big, t=(big + 1) / sc.run.control_hz,
                        role="leader" if aid in sc.leader_ids else "follower",
                        z1=np.full(3, 400.0), z2=np.zeros(3), z3=np.zeros(3),
                        xi=np.zeros(12), zeta=np.zeros(6))
                    sess.put(wire.key_estimate(sc.name, aid), wire.encode(est))
                time.sleep(0.1)
        finally:
            sess.close()

    rec, facts = _run_under_attack(tmp_path, sc, tmp_path / "offboard-1.log", attack, dur, off,
                                   realtime=True)
    _safe_and_normal(tmp_path, sc, rec, facts, dur)
    for aid in sc.ids:
        text = (tmp_path / f"offboard-{aid}.log").read_text()
        assert "Zenoh: dropped" in text and "implausible" in text, aid
        assert "truth lost" not in text, aid


def _daemon_pid(agent: int, off: int) -> int:
    want = ["-m offboard ", "--agent", str(agent), "--port-offset", str(off)]
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            # NUL-separated, or one string when the title was set (a forked child's)
            raw = (entry / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        joined = " ".join(raw.split("\0"))
        argv = joined.split()
        if all(w in argv for w in want[1:]) and want[0] in joined:
            return int(entry.name)
    raise AssertionError(f"no offboard daemon for agent {agent} at offset {off}")


def test_stopped_daemon_gets_its_vehicle_back_into_offboard(tmp_path: Path) -> None:
    """kill -STOP of daemon 4 for 2 s in real time: its vehicle trips the offboard-loss
    failsafe (HOLD); once the daemon runs again it asks for OFFBOARD and gets it."""
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    dur = 12.0
    victim = 4

    def attack() -> None:
        time.sleep(1.0)
        pid = _daemon_pid(victim, off)
        os.kill(pid, signal.SIGSTOP)
        try:
            time.sleep(2.0)
        finally:
            os.kill(pid, signal.SIGCONT)

    log = tmp_path / f"offboard-{victim}.log"
    rec, facts = _run_under_attack(tmp_path, sc, log, attack, dur, off, realtime=True)
    assert "HOLD" in _modes(tmp_path)[victim]  # the failsafe did trip
    _safe_and_normal(tmp_path, sc, rec, facts, dur)  # ... and it is back in OFFBOARD
    text = (tmp_path / f"offboard-{victim}.log").read_text()
    assert "back in OFFBOARD after a failsafe" in text


def _daemon(tmp: Path, off: int, key: Path, name: str) -> ChildProcess:
    """One daemon (agent 1) of a real-time swarm, Zenoh as a lone listening peer."""
    zen = f"tcp/127.0.0.1:{free_tcp_port()}"
    argv = [*python_entry("offboard.cli"), "--scenario", CUBE8, "--agent", "1",
            "--port-offset", str(off), "--realtime", "--zenoh-mode", "peer",
            "--zenoh-listen", zen, "--zenoh-connect", "--signing-key", str(key)]
    return start_child(argv, tmp / f"{name}.log")


def test_signed_vehicle_link(tmp_path: Path, sim_factory: Any) -> None:
    """vehicle-sim and a daemon with the same key lock their link and the vehicle sees
    signed setpoints; a daemon with another key drops every frame as badly signed and
    never locks (nor sends anything)."""
    good, bad = tmp_path / "good.key", tmp_path / "bad.key"
    generate_key(good)
    generate_key(bad)
    off = free_port_offset()
    sim = sim_factory(["--signing-key", str(good), "--no-zenoh", "--vehicles", "1"],
                      offset=off)
    stop = threading.Event()
    for key, name, want in ((bad, "wrong", "bad signature"), (good, "right", "link locked")):
        proc = _daemon(tmp_path, off, key, name)
        try:
            assert _wait_text(tmp_path / f"{name}.log", want, 40.0, stop), name
            time.sleep(1.0)
            text = (tmp_path / f"{name}.log").read_text()
            if name == "wrong":
                assert "link locked" not in text
            else:  # its signed SET_MESSAGE_INTERVAL was acknowledged as accepted
                assert "bad signature" not in text and "not accepted" not in text
        finally:
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(20) == 0
    assert sim.proc.poll() is None
