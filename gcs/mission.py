"""Distributed mission runs: ``gcs mission run SCENARIO`` without ``--inproc``.

Starts, as real processes: one ``vehicle-sim`` (lockstep by default) and one
``offboard`` daemon per agent; hosts the Zenoh router itself (clients connect to it);
records every step's truth, estimates and statuses from Zenoh; shows a progress bar;
stops everything at the end, on Ctrl-C, or when a child dies (naming it, exit 1).

Run directory: ``metrics.json``, ``series.npz`` (truth, estimates, commands),
``vehicle_<id>.tlog`` (each daemon's MAVLink link, readable by pymavlink's tools) and
one ``<process>.log`` per child.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcs.procs import ProcessGroup, python_entry
from gcs.router import open_router
from swarm_common import wire
from swarm_common.ports import vehicle_ports
from swarm_common.scenario import Scenario

ZENOH_BASE = 7447


class MissionError(RuntimeError):
    """A run failed: a child died or the run stalled. ``str()`` names the culprit."""


def port_free(port: int, kind: int = socket.SOCK_DGRAM) -> bool:
    s = socket.socket(socket.AF_INET, kind)
    try:
        s.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def check_ports(sc: Scenario, offset: int) -> None:
    """Raise MissionError naming the first busy port of this run."""
    for a in sc.agents:
        vp = vehicle_ports(a.id, offset)
        for p in (vp.api_local, vp.api_remote, vp.gcs_local):
            if not port_free(p):
                raise MissionError(f"UDP port {p} (vehicle {a.id}) is busy; try --port-offset")
    for p in (ZENOH_BASE + offset, ZENOH_BASE + offset + 1):
        if not port_free(p, socket.SOCK_STREAM):
            raise MissionError(f"TCP port {p} (Zenoh) is busy; try --port-offset")


@dataclass
class Recorder:
    """Collects the Zenoh traffic of a run, indexed by control step."""

    sc: Scenario
    steps: int
    truth: dict[int, wire.Truth] = field(default_factory=dict)
    est: dict[int, dict[int, wire.Estimate]] = field(default_factory=dict)
    status: dict[int, dict[int, wire.Status]] = field(default_factory=dict)
    last_status: dict[int, wire.Status] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    max_step: int = -1

    def on_truth(self, sample: Any) -> None:
        try:
            msg = wire.decode(sample.payload.to_bytes())
        except wire.WireError:
            return
        if isinstance(msg, wire.Truth) and 0 <= msg.step <= self.steps:
            with self.lock:
                self.truth[msg.step] = msg
                self.max_step = max(self.max_step, msg.step)

    def on_estimate(self, sample: Any) -> None:
        try:
            msg = wire.decode(sample.payload.to_bytes())
        except wire.WireError:
            return
        if isinstance(msg, wire.Estimate):
            with self.lock:
                self.est.setdefault(msg.step, {})[msg.id] = msg

    def on_status(self, sample: Any) -> None:
        try:
            msg = wire.decode(sample.payload.to_bytes())
        except wire.WireError:
            return
        if isinstance(msg, wire.Status):
            with self.lock:
                self.status.setdefault(msg.step, {})[msg.id] = msg
                self.last_status[msg.id] = msg


def progress(t: float, duration: float, wall: float) -> None:
    frac = min(1.0, t / duration) if duration > 0 else 1.0
    bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
    rate = t / wall if wall > 0 else 0.0
    sys.stderr.write(f"\r[{bar}] {t:6.2f}/{duration:.1f} s  {rate:5.1f}x real time")
    sys.stderr.flush()


def run_distributed(
    sc: Scenario,
    out_dir: Path,
    method: str,
    seed: int | None,
    duration: float,
    realtime: bool = False,
    port_offset: int = 0,
    kill_agent: int | None = None,
    kill_at: float | None = None,
    show_progress: bool = True,
    stall_timeout: float = 20.0,
) -> tuple[Recorder, dict[str, Any]]:
    """Run the mission as real processes; return the recorder and run facts."""
    out_dir.mkdir(parents=True, exist_ok=True)
    check_ports(sc, port_offset)
    router_ep = f"tcp/127.0.0.1:{ZENOH_BASE + port_offset}"
    sim_ep = f"tcp/127.0.0.1:{ZENOH_BASE + port_offset + 1}"
    try:
        router = open_router([router_ep])
    except RuntimeError as exc:
        raise MissionError(str(exc)) from None
    steps = int(round(duration * sc["scenario"]["control_hz"]))
    rec = Recorder(sc, steps)
    swarm = f"{sc.name}-{port_offset}"
    subs = [
        router.declare_subscriber(wire.key_truth(swarm), rec.on_truth),
        router.declare_subscriber(wire.key_estimate(swarm, "*"), rec.on_estimate),
        router.declare_subscriber(wire.key_status(swarm, "*"), rec.on_status),
    ]
    group = ProcessGroup(out_dir)
    seed_args = ["--seed", str(seed)] if seed is not None else []
    facts: dict[str, Any] = {"failed_agents": [], "killed_agents": []}
    t_wall0 = time.monotonic()
    try:
        sim_argv = [
            *python_entry("vehicle_sim.cli"),
            "--scenario",
            sc.path,
            "--port-offset",
            str(port_offset),
            "--swarm",
            swarm,
            "--zenoh-listen",
            sim_ep,
            "--zenoh-connect",
            router_ep,
            "--duration",
            f"{duration + 1.0}",
            *seed_args,
        ]
        if not realtime:
            sim_argv.append("--lockstep")
        group.start("vehicle-sim", sim_argv)
        for a in sc.agents:
            argv = [
                *python_entry("offboard.cli"),
                "--scenario",
                sc.path,
                "--agent",
                str(a.id),
                "--port-offset",
                str(port_offset),
                "--swarm",
                swarm,
                "--method",
                method,
                "--zenoh-connect",
                router_ep,
                "--tlog",
                str(out_dir / f"vehicle_{a.id}.tlog"),
                *seed_args,
            ]
            if realtime:
                argv.append("--realtime")
            group.start(f"offboard-{a.id}", argv)
        last_progress = -1
        last_change = time.monotonic()
        killed = False
        while True:
            time.sleep(0.05)
            with rec.lock:
                k = rec.max_step
            if k != last_progress:
                last_change = time.monotonic()
                last_progress = k
                if show_progress:
                    progress(max(k, 0) * sc.control_dt, duration, time.monotonic() - t_wall0)
            if k >= steps:
                break
            if kill_agent is not None and not killed and k * sc.control_dt >= (kill_at or 0.0):
                group.kill(f"offboard-{kill_agent}")
                facts["killed_agents"].append(kill_agent)
                killed = True
            for child in group.dead():
                if child.name == f"offboard-{kill_agent}" and killed:
                    continue
                raise MissionError(
                    f"{child.name} exited with code {child.proc.returncode}; "
                    f"last lines of {child.log_path}:\n{group.tail(child)}"
                )
            if time.monotonic() - last_change > stall_timeout:
                raise MissionError(
                    f"run stalled at step {k} for {stall_timeout:.0f} s; see logs in {out_dir}"
                )
        if show_progress:
            sys.stderr.write("\n")
    finally:
        group.stop()
        for s in subs:
            try:
                s.undeclare()
            except Exception:  # noqa: BLE001
                pass
        router.close()
    facts["wall_s"] = time.monotonic() - t_wall0
    if killed:
        facts["failed_agents"] = list(facts["killed_agents"])
    return rec, facts


def recorder_series(rec: Recorder, sc: Scenario) -> dict[str, np.ndarray]:
    """Truth/estimate/status time series as arrays (K = recorded steps)."""
    steps = sorted(s for s in rec.truth if s <= rec.steps)
    n = sc.n
    idx = {a.id: k for k, a in enumerate(sc.agents)}
    k_n = len(steps)
    out: dict[str, np.ndarray] = {
        "t": np.array([rec.truth[s].t for s in steps]),
        "p": np.stack([rec.truth[s].p for s in steps]) if steps else np.zeros((0, n, 3)),
        "v": np.stack([rec.truth[s].v for s in steps]) if steps else np.zeros((0, n, 3)),
        "att": np.stack([rec.truth[s].att for s in steps]) if steps else np.zeros((0, n, 3)),
        "thrust": np.stack([rec.truth[s].thrust for s in steps]) if steps else np.zeros((0, n)),
        "lumped": np.stack([rec.truth[s].lumped for s in steps]) if steps else np.zeros((0, n, 3)),
    }
    z1 = np.full((k_n, n, 3), np.nan)
    z2 = np.full((k_n, n, 3), np.nan)
    z3 = np.full((k_n, n, 3), np.nan)
    u = np.full((k_n, n, 3), np.nan)
    p_des = np.full((k_n, n, 3), np.nan)
    for r, s in enumerate(steps):
        for aid, st in rec.status.get(s, {}).items():
            if aid in idx:
                u[r, idx[aid]] = st.u
                p_des[r, idx[aid]] = st.p_des
                z1[r, idx[aid]] = st.z1
        for aid, e in rec.est.get(s - 1, {}).items():  # estimate for t_s, made at step s-1
            if aid in idx:
                z2[r, idx[aid]] = e.z2
                z3[r, idx[aid]] = e.z3
    out.update({"z1": z1, "z2": z2, "z3": z3, "u": u, "p_des": p_des})
    return out


def write_run(out_dir: Path, metrics: dict[str, Any], series: dict[str, np.ndarray]) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2, sort_keys=True))
    np.savez_compressed(out_dir / "series.npz", **series)
