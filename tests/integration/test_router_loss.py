"""The router dies in the middle of a real-time mission (docs/security.md, "Losing the
runner or the router"): ``gcs router`` as its own process, ``vehicle-sim`` and eight
``offboard --realtime`` daemons over 127.0.0.1. Once the swarm flies, the router gets
SIGKILL; every daemon holds, then lands its vehicle on its slot of the coordinated landing
plan from its own ODOMETRY, and disarms it. A MAVLink observer on the simulator's GCS port
(the simulator keeps running) records every vehicle's position throughout."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path
from typing import IO

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from conftest import CUBE8, ROOT, free_port_offset, stop_processes  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from gcs.launch_spec import LaunchSpec  # noqa: E402
from swarm_common.ports import GCS_PORT  # noqa: E402
from swarm_common.scenario import load_scenario  # noqa: E402

pytestmark = pytest.mark.timeout(240)

MIN_DIST_M = 0.5
ARMED_FLAG = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
AUTOPILOT = mavutil.mavlink.MAV_COMP_ID_AUTOPILOT1
LANDED_Z_M = 0.1
FLY_BEFORE_KILL_S = 8.0  # mission time at which the router is killed
LAND_TIMEOUT_S = 90.0  # wall s after the kill (landing ≈ 3 s hold + 13 s on a loaded host)
PLAN_LINE = re.compile(r"runner/router lost since t=([\d.]+) s: landing on odometry, "
                       r"t_L=([\d.]+) s")


class Observer(threading.Thread):
    """Every vehicle's LOCAL_POSITION_NED and HEARTBEAT from the simulator's GCS stream;
    the minimum pairwise distance over snapshots (each position carried to the newest
    stamp at its own velocity, so the vehicles' stream phases do not matter)."""

    def __init__(self, port: int, ids: list[int]) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
        self.ids = ids
        self.pos: dict[int, tuple[float, np.ndarray, np.ndarray]] = {}  # t, p NED, v NED
        self.armed: dict[int, bool] = {}
        self.min_dist = float("inf")  # since the last reset_min
        self.min_at = 0.0  # mission time (s) of that minimum
        self.samples = 0
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
            with self.lock:
                if m.get_type() == "HEARTBEAT":
                    self.armed[sysid] = bool(m.base_mode & ARMED_FLAG)
                else:
                    self.pos[sysid] = (m.time_boot_ms * 1e-3, np.array([m.x, m.y, m.z]),
                                       np.array([m.vx, m.vy, m.vz]))
                    self._distance()

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


def _start(argv: list[str], log: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
    out: IO[bytes] = log.open("wb")
    return subprocess.Popen(argv, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
                            env={**os.environ, **(env or {})})


def _wait(pred: object, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():  # type: ignore[operator]
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def _port_open(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


@dataclass
class Swarm:
    """A flying real-time swarm: its observer, router process, daemons' processes and logs."""

    obs: Observer
    router: subprocess.Popen
    procs: list[subprocess.Popen]
    logs: list[Path]


@contextmanager
def _flying_swarm(tmp_path: Path) -> Iterator[Swarm]:
    """``gcs router``, ``vehicle-sim`` and eight ``offboard --realtime`` daemons (cube8,
    dcbf), flying and armed past FLY_BEFORE_KILL_S; everything stopped afterwards."""
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    spec = LaunchSpec(sc, port_offset=off, lockstep=False, run_dir=tmp_path, method="dcbf")
    obs = Observer(GCS_PORT + off, list(sc.ids))
    obs.start()
    router = _start([sys.executable, "-m", "gcs.cli", "router", "--listen",
                     spec.router_endpoint], tmp_path / "router.log")
    procs: list[subprocess.Popen] = []
    try:
        _wait(lambda: _port_open(spec.router_port) or router.poll() is not None, 30, "router")
        assert router.poll() is None, (tmp_path / "router.log").read_text()
        for name, argv in spec.processes():
            procs.append(_start(argv, tmp_path / f"{name}.log"))
        logs = [tmp_path / f"offboard-{i}.log" for i in sc.ids]
        _wait(lambda: all(p.exists() and "ARM accepted" in p.read_text() for p in logs), 90,
              "every daemon to arm")
        _wait(lambda: obs.time_s() >= FLY_BEFORE_KILL_S, 60, "the swarm to fly")
        # the observer learns of an arm from the next 1 Hz HEARTBEAT, after the daemon's log
        _wait(lambda: all(obs.armed.get(i) for i in sc.ids), 30, "every HEARTBEAT to say armed")
        yield Swarm(obs, router, procs, logs)
    finally:
        stop_processes(procs)
        if router.poll() is None:
            router.send_signal(signal.SIGCONT)
            router.kill()
        router.wait(10)
        obs.close()


def _collisions(tmp_path: Path) -> int:
    sim_log = (tmp_path / "vehicle-sim.log").read_text(errors="replace")
    counts = re.findall(r"collisions=(\d+)", sim_log)
    assert counts, sim_log[-2000:]
    return int(counts[-1])


def test_router_kill_lands_every_vehicle_safely(tmp_path: Path) -> None:
    with _flying_swarm(tmp_path) as sw:
        obs = sw.obs
        before, before_at = obs.reset_min()
        sw.router.send_signal(signal.SIGKILL)
        sw.router.wait(10)
        t_kill = obs.time_s()
        _wait(obs.landed, LAND_TIMEOUT_S, "every vehicle landed and disarmed")
        t_landed = obs.time_s()
        assert all(p.poll() is None for p in sw.procs), "a process died"
    assert _collisions(tmp_path) == 0
    assert obs.samples > 100 and obs.min_dist >= MIN_DIST_M, obs.min_dist
    plans = [PLAN_LINE.search(p.read_text()) for p in sw.logs]
    assert all(plans), [p.name for p, m in zip(sw.logs, plans, strict=True) if m is None]
    t_l = [float(m.group(2)) for m in plans if m is not None]
    assert max(t_l) - min(t_l) <= 0.5  # one land time (within a few steps), no communication
    print(f"router killed at t={t_kill:.2f} s, t_L={min(t_l):.2f}..{max(t_l):.2f} s, all "
          f"landed and disarmed by t={t_landed:.2f} s; min distance {obs.min_dist:.3f} m "
          f"over {obs.samples} snapshots after the kill ({before:.3f} m at t={before_at:.2f} s "
          "before it); collisions 0")


STALL_S = 0.4  # wall s the router is stopped: past the stall threshold, short of the loss


def test_router_stall_brakes_then_flies_on(tmp_path: Path) -> None:
    """SIGSTOP of the router for 0.4 s (truth 10–25 periods late on every daemon): each
    daemon brakes to a hold on its own odometry, then flies on when truth is back; nobody
    lands, nobody collides, and the formation flies on well apart."""
    with _flying_swarm(tmp_path) as sw:
        obs = sw.obs
        sw.router.send_signal(signal.SIGSTOP)
        time.sleep(STALL_S)
        sw.router.send_signal(signal.SIGCONT)
        t_stall = obs.time_s()
        _wait(lambda: all("truth back" in p.read_text() for p in sw.logs), 30,
              "every daemon to fly on")
        _wait(lambda: obs.time_s() >= t_stall + 4.0, 60, "4 s more of flight")
        assert all(p.poll() is None for p in sw.procs), "a process died"
        assert all(obs.armed.get(i) for i in obs.ids)
    texts = [p.read_text() for p in sw.logs]
    assert all("braking to a hold" in t for t in texts)
    assert not any("landing on odometry" in t for t in texts)
    assert _collisions(tmp_path) == 0
    assert obs.samples > 100 and obs.min_dist >= MIN_DIST_M, obs.min_dist
    print(f"router stopped {STALL_S} s at t={t_stall:.2f} s: every daemon braked and flew "
          f"on; min distance {obs.min_dist:.3f} m over {obs.samples} snapshots")
