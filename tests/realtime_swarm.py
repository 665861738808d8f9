"""A real-time cube-style swarm as the product runs it, for tests and benchmarks that cut
its router: ``gcs router`` as its own process, ``vehicle-sim`` and one ``offboard
--realtime`` daemon per agent over 127.0.0.1, and a MAVLink observer on the simulator's
GCS port that keeps every vehicle's position and arming state (the simulator keeps
running whatever happens to the router)."""

from __future__ import annotations

import os
import re
import signal
import socket
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from conftest import CUBE8, free_port_offset, start_child, stop_processes  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from gcs.mission.launch_spec import LaunchSpec  # noqa: E402
from gcs.mission.procs import ChildProcess  # noqa: E402
from swarm_common.ports import GCS_PORT, vehicle_ports  # noqa: E402
from swarm_common.scenario.model import load_scenario  # noqa: E402

ARMED_FLAG = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
AUTOPILOT = mavutil.mavlink.MAV_COMP_ID_AUTOPILOT1
LANDED_Z_M = 0.1
POSITION_HZ = 20.0  # LOCAL_POSITION_NED asked of every vehicle


class Observer(threading.Thread):
    """Every vehicle's LOCAL_POSITION_NED and HEARTBEAT from the simulator's GCS stream;
    the minimum pairwise distance over snapshots (each position carried to the newest
    stamp at its own velocity, so the vehicles' stream phases do not matter)."""

    def __init__(self, port: int, ids: list[int]) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
        self.ids = ids
        self.offset = port - GCS_PORT  # the swarm's port offset
        self.pos: dict[int, tuple[float, np.ndarray, np.ndarray]] = {}  # t, p NED, v NED
        self.armed: dict[int, bool] = {}
        self.min_dist = float("inf")  # since the last reset_min
        self.min_at = 0.0  # mission time (s) of that minimum
        self.samples = 0
        self.asked: dict[int, float] = {}  # sysid -> when LOCAL_POSITION_NED was last asked
        self.heard: dict[int, float] = {}  # sysid -> when its last position arrived
        self.halt = threading.Event()
        self.lock = threading.Lock()

    def run(self) -> None:
        while not self.halt.is_set():
            m = self.conn.recv_match(type=["LOCAL_POSITION_NED", "HEARTBEAT"], blocking=True,
                                     timeout=0.2)
            if m is None:
                continue
            sysid = m.get_srcSystem()
            if sysid not in self.ids or m.get_srcComponent() != AUTOPILOT:
                continue  # the daemons' own HEARTBEATs (component 191) are forwarded too
            if m.get_type() == "HEARTBEAT":
                self._ask_positions(sysid)
            with self.lock:
                if m.get_type() == "HEARTBEAT":
                    self.armed[sysid] = bool(m.base_mode & ARMED_FLAG)
                else:
                    self.pos[sysid] = (m.time_boot_ms * 1e-3, np.array([m.x, m.y, m.z]),
                                       np.array([m.vx, m.vy, m.vz]))
                    self.heard[sysid] = time.monotonic()
                    self._distance()

    def _ask_positions(self, sysid: int) -> None:
        """As a ground station does: LOCAL_POSITION_NED at POSITION_HZ from this vehicle
        (its GCS link starts from PX4's normal set, 1 Hz), asked again while the vehicle's
        positions do not come that fast (a request lost, a vehicle restarted)."""
        now = time.monotonic()
        last = self.pos.get(sysid)
        fresh = last is not None and now - self.heard.get(sysid, 0.0) < 0.5
        if fresh or now - self.asked.get(sysid, -10.0) < 2.0:
            return
        self.asked[sysid] = now
        msg = self.conn.mav.command_long_encode(
            sysid, AUTOPILOT, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            mavutil.mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 1e6 / POSITION_HZ, 0, 0, 0, 0, 0)
        try:
            # to the port the vehicle's GCS link sends from (swarm_common.ports)
            dest = ("127.0.0.1", vehicle_ports(sysid, self.offset).gcs_local)
            self.conn.port.sendto(msg.pack(self.conn.mav), dest)
        except OSError:
            pass

    def _distance(self) -> None:
        if len(self.pos) < len(self.ids):
            return
        t_new = max(t for t, _, _ in self.pos.values())
        if any(t_new - t > 0.2 for t, _, _ in self.pos.values()):
            return  # a vehicle's stream stalled: not a snapshot
        p = {i: pv + vv * (t_new - t) for i, (t, pv, vv) in self.pos.items()}
        d = min(float(np.linalg.norm(p[i] - p[j])) for i, j in combinations(self.ids, 2))
        if d < self.min_dist:
            self.min_dist, self.min_at = d, t_new
        self.samples += 1

    def reset_min(self) -> tuple[float, float]:
        """(minimum distance, its time) so far; start a new minimum."""
        with self.lock:
            out = (self.min_dist, self.min_at)
            self.min_dist, self.samples = float("inf"), 0
            return out

    def time_s(self) -> float:
        with self.lock:
            return max((t for t, _, _ in self.pos.values()), default=0.0)

    def landed_one(self, i: int) -> bool:
        """Vehicle ``i`` on the ground (z NED ≥ −LANDED_Z_M) and disarmed."""
        with self.lock:
            return i in self.pos and -self.pos[i][1][2] < LANDED_Z_M and self.armed.get(i) is False

    def landed(self) -> bool:
        """Every vehicle on the ground (z NED ≥ −LANDED_Z_M) and disarmed."""
        with self.lock:
            return (len(self.pos) == len(self.ids) and len(self.armed) == len(self.ids)
                    and all(-p[2] < LANDED_Z_M for _, p, _ in self.pos.values())
                    and not any(self.armed.values()))

    def close(self) -> None:
        self.halt.set()
        self.join(5)
        self.conn.close()


def wait_for(pred: object, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():  # type: ignore[operator]
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def port_open(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


@dataclass
class Swarm:
    """A flying real-time swarm: its observer, router process, daemons' processes and logs."""

    obs: Observer
    router: ChildProcess
    procs: list[ChildProcess]
    logs: list[Path]


@contextmanager
def flying_swarm(tmp_path: Path, fly_s: float, scenario: str = CUBE8, method: str = "dcbf",
                 extra_args: dict[int, list[str]] | None = None,
                 all_armed: bool = True) -> Iterator[Swarm]:
    """``gcs router``, ``vehicle-sim`` and the daemons of ``scenario`` in real time,
    flying past mission time ``fly_s`` (and every vehicle armed, unless not ``all_armed``);
    everything stopped afterwards. ``extra_args``: agent id -> flags appended to that
    agent's daemon command line."""
    sc = load_scenario(scenario)
    off = free_port_offset()
    spec = LaunchSpec(sc, port_offset=off, lockstep=False, run_dir=tmp_path, method=method)
    obs = Observer(GCS_PORT + off, list(sc.ids))
    obs.start()
    router = start_child([sys.executable, "-m", "gcs.cli", "router", "--listen",
                     spec.router_endpoint], tmp_path / "router.log")
    procs: list[ChildProcess] = []
    try:
        wait_for(lambda: port_open(spec.router_port) or router.poll() is not None, 30, "router")
        assert router.poll() is None, (tmp_path / "router.log").read_text()
        for name, argv in spec.processes():
            who = name.removeprefix("offboard-")  # one agent per process here
            more = (extra_args or {}).get(int(who), []) if who.isdigit() else []
            procs.append(start_child(argv + more,
                               tmp_path / f"{name}.log"))
        logs = [tmp_path / f"offboard-{i}.log" for i in sc.ids]
        wait_for(lambda: all(p.exists() and "ARM accepted" in p.read_text() for p in logs), 90,
              "every daemon to arm")
        wait_for(lambda: obs.time_s() >= fly_s, 60, "the swarm to fly")
        # the observer learns of an arm from the next 1 Hz HEARTBEAT, after the daemon's log
        if all_armed:
            wait_for(lambda: all(obs.armed.get(i) for i in sc.ids), 30,
                     "every HEARTBEAT to say armed")
        yield Swarm(obs, router, procs, logs)
    finally:
        stop_processes(procs)
        if router.poll() is None:
            router.send_signal(signal.SIGCONT)
            router.kill()
        router.wait(10)
        obs.close()


def collisions(tmp_path: Path) -> int:
    sim_log = (tmp_path / "vehicle-sim.log").read_text(errors="replace")
    counts = re.findall(r"collisions=(\d+)", sim_log)
    assert counts, sim_log[-2000:]
    return int(counts[-1])
