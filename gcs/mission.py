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

from gcs.metrics import Series, compute_metrics
from gcs.procs import ProcessGroup, python_entry
from gcs.router import open_router
from offboard.bearing import formation_from_scenario
from swarm_common import wire
from swarm_common.ports import port_free, swarm_udp_ports
from swarm_common.scenario import Scenario
from vehicle_sim.dynamics import SwarmDynamics

ZENOH_BASE = 7447


class MissionError(RuntimeError):
    """A run failed: a child died or the run stalled. ``str()`` names the culprit."""


def check_ports(sc: Scenario, offset: int) -> None:
    """Raise MissionError naming the first busy port of this run."""
    for a in sc.agents:
        for p in swarm_udp_ports([a.id], offset)[1:]:
            if not port_free(p):
                raise MissionError(f"UDP port {p} (vehicle {a.id}) is busy; try --port-offset")
    for p in (ZENOH_BASE + offset, ZENOH_BASE + offset + 1):
        if not port_free(p, socket.SOCK_STREAM, allow_time_wait=True):
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
    seed: int | None = None
    raw: list[bytes] = field(default_factory=list)

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
        # kept raw and decoded after the run: the recorder shares two cores with the
        # swarm, and decoding 16 payloads per step here cost ~2 ms of CPU per step
        self.raw.append(sample.payload.to_bytes())

    on_status = on_estimate

    def finalize(self) -> None:
        """Decode what was kept raw (arrival order; a re-sent estimate is identical)."""
        raw, self.raw = self.raw, []
        for data in raw:
            try:
                msg = wire.decode(data)
            except wire.WireError:
                continue
            if isinstance(msg, wire.Estimate):
                self.est.setdefault(msg.step, {})[msg.id] = msg
            elif isinstance(msg, wire.Status):
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
    steps = int(round(duration * sc.run.control_hz))
    rec = Recorder(sc, steps, seed=seed)
    swarm = sc.name
    subs = [
        router.declare_subscriber(wire.key_truth(swarm), rec.on_truth),
        router.declare_subscriber(wire.key_estimate(swarm, "*"), rec.on_estimate),
        router.declare_subscriber(wire.key_status(swarm, "*"), rec.on_status),
    ]
    group = ProcessGroup(out_dir)
    seed_args = ["--seed", str(seed)] if seed is not None else []
    facts: dict[str, Any] = {"failed_agents": [], "killed_agents": []}
    t_wall0 = time.monotonic()
    cpu0 = time.process_time()
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
            "--stats-out",
            str(out_dir / "vehicle-sim-stats.json"),
            "--step-timeout",
            "1.0",  # > the daemons' neighbour timeout (0.45 s): a dead agent costs one wait
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
        t_run0 = time.monotonic()
        t_first: float | None = None
        k_first = 0
        killed = False
        while True:
            time.sleep(0.05)
            with rec.lock:
                k = rec.max_step
            if k >= 1 and t_first is None:
                t_first, k_first = time.monotonic(), k
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
        facts["run_wall_s"] = time.monotonic() - t_run0
        if t_first is not None:
            stepping = time.monotonic() - t_first
            facts["stepping_wall_s"] = stepping
            facts["stepping_realtime_factor"] = (steps - k_first) * sc.control_dt / stepping
        facts["processes"] = group.usage()
        facts["processes"]["gcs (router + recorder)"] = {
            "cpu_s": time.process_time() - cpu0,
            "peak_rss_mib": _peak_rss_mib(),
        }
    finally:
        group.stop()
        for s in subs:
            try:
                s.undeclare()
            except Exception:  # noqa: BLE001
                pass
        router.close()
        rec.finalize()
    facts["wall_s"] = time.monotonic() - t_wall0
    stats_path = out_dir / "vehicle-sim-stats.json"
    if stats_path.exists():
        try:
            facts["simulator"] = json.loads(stats_path.read_text())
        except ValueError:
            pass
    if killed:
        facts["failed_agents"] = list(facts["killed_agents"])
    return rec, facts


def _peak_rss_mib() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def recorder_series(rec: Recorder, sc: Scenario) -> Series:
    """The recorded run as the in-process runner's :class:`~gcs.metrics.Series`.

    Row k holds truth(k), the estimates valid at t_k (published at step k−1), the
    statuses of step k and the minimum pair distance over (t_k, t_k+1] (carried by
    truth(k+1)). Rows use the float32 values that crossed the wire, as in-process.
    """
    form = formation_from_scenario(sc)
    lid = form.leader_idx
    steps = [k for k in range(rec.steps) if k in rec.truth]
    kk = len(steps)
    n = sc.n
    idx = {a.id: i for i, a in enumerate(sc.agents)}

    def z(*shape: int) -> np.ndarray:
        return np.full((kk, *shape), np.nan)

    ser = Series(
        t=np.array([rec.truth[k].t for k in steps]), p=z(n, 3), v=z(n, 3), p_des=z(n, 3),
        v_des=z(n, 3), z1=z(n, 3), z2=z(n, 3), lumped_est=z(n, 3), lumped_true=z(n, 3),
        u=z(n, 3), thrust=z(n), tilt_deg=z(n), min_dist=z(), h_min=z(n), solve_us=z(n),
        fallback=np.zeros((kk, n), bool),
    )
    for r, k in enumerate(steps):
        tr = rec.truth[k]
        ser.p[r], ser.v[r] = tr.p, tr.v
        ser.p_des[r] = form.desired_positions(tr.p[lid])
        ser.v_des[r] = form.desired_positions(tr.v[lid])
        ser.lumped_true[r] = tr.lumped
        ser.thrust[r] = tr.thrust
        ser.tilt_deg[r] = np.degrees(
            np.arccos(np.clip(np.cos(tr.att[:, 0]) * np.cos(tr.att[:, 1]), -1, 1))
        )
        nxt = rec.truth.get(k + 1)
        ser.min_dist[r] = nxt.min_dist if nxt is not None else np.nan
        for aid, e in rec.est.get(k - 1, {}).items():
            if aid in idx:
                ser.z1[r, idx[aid]], ser.z2[r, idx[aid]] = e.z1, e.z2
        for aid, st in rec.status.get(k, {}).items():
            if aid in idx:
                i = idx[aid]
                ser.u[r, i] = st.u
                ser.lumped_est[r, i] = st.lumped
                ser.h_min[r, i] = st.h_min
                ser.solve_us[r, i] = st.qp_solve_us
                ser.fallback[r, i] = st.qp_status in ("relaxed", "fallback")
    # Real time: an agent may skip a stamp (late cycle), leaving a row without its
    # message; hold the last value (lockstep runs have none missing).
    for arr in (ser.z1, ser.z2, ser.u, ser.lumped_est, ser.h_min, ser.solve_us):
        for r in range(1, kk):
            gap = np.isnan(arr[r])
            if np.any(gap):
                arr[r][gap] = arr[r - 1][gap]
    ser.u[np.isnan(ser.u)] = 0.0  # before a daemon's first status: no command known
    return ser


def recorded_metrics(
    rec: Recorder, sc: Scenario, wall_s: float, duration: float
) -> tuple[dict[str, Any], Series]:
    """Metrics of a distributed run, computed by the same function as in process."""
    ser = recorder_series(rec, sc)
    form = formation_from_scenario(sc)
    veh = sc.vehicle
    last = rec.truth[max(rec.truth)] if rec.truth else None
    fols = form.follower_idx
    zeta_true = _zeta_true(sc, rec)
    zeta_est = np.zeros((sc.n, 6))
    fallbacks = 0
    final_est = rec.est.get(rec.steps - 1, {})
    for a_id, e in final_est.items():
        zeta_est[sc.index_of(a_id)] = e.zeta
    for st in rec.last_status.values():
        fallbacks += st.fallbacks
    valid = ~np.isnan(ser.min_dist)
    if not np.all(valid):  # a run cut short: drop the incomplete tail
        ser = Series(**{k: v[valid] for k, v in ser.as_dict().items()})
    metrics = compute_metrics(
        ser, fols, sc.control_dt, veh.mass_kg, veh.gravity_mps2,
        last.collisions if last else 0, zeta_true, zeta_est, fallbacks, wall_s, duration,
    )
    return metrics, ser


def _zeta_true(sc: Scenario, rec: Recorder) -> np.ndarray:
    """The simulator's true ζ (same seeded draw as vehicle_sim.dynamics)."""
    return SwarmDynamics(sc, seed=rec.seed).zeta


def write_run(out_dir: Path, metrics: dict[str, Any], series: dict[str, np.ndarray]) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2, sort_keys=True))
    np.savez_compressed(out_dir / "series.npz", **series)


def default_out_dir(sc: Scenario, method: str) -> Path:
    return Path("runs") / f"{sc.name}-{method}-{time.strftime('%Y%m%d-%H%M%S')}"


def run_and_score(
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
) -> dict[str, Any]:
    """One distributed run -> metrics.json + series.npz in ``out_dir``; returns the document."""
    rec, facts = run_distributed(
        sc, out_dir, method, seed, duration, realtime=realtime, port_offset=port_offset,
        kill_agent=kill_agent, kill_at=kill_at, show_progress=show_progress,
    )
    metrics, ser = recorded_metrics(rec, sc, facts["wall_s"], duration)
    doc = {
        "scenario": sc.name,
        "method": method,
        "seed": sc.seed if seed is None else seed,
        "mode": "realtime" if realtime else "lockstep",
        "metrics": metrics,
        "run": facts,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
    np.savez_compressed(out_dir / "series.npz", **ser.as_dict())
    return doc


def _json_default(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(type(x))


def cli_run(args: Any, sc: Scenario) -> int:
    """``gcs mission run SCENARIO`` (distributed): the hook gcs.cli calls."""
    method = args.method or sc.controller.method
    duration = float(sc.run.duration_s if args.duration is None else args.duration)
    if args.kill_agent is not None and args.kill_agent not in sc.ids:
        print(f"gcs mission run: --kill-agent {args.kill_agent}: not an agent of {sc.path} "
              f"{sc.ids}", file=sys.stderr)
        return 2
    if args.kill_at is not None and args.kill_agent is None:
        print("gcs mission run: --kill-at needs --kill-agent", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else default_out_dir(sc, method)
    try:
        doc = run_and_score(
            sc, out, method, args.seed, duration, realtime=args.realtime,
            port_offset=args.port_offset, kill_agent=args.kill_agent, kill_at=args.kill_at,
            show_progress=True,
        )
    except KeyboardInterrupt:
        print("\ngcs mission run: interrupted; every process stopped", file=sys.stderr)
        return 130
    except MissionError as exc:
        print(f"\ngcs mission run: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out}/metrics.json, series.npz, vehicle_*.tlog, *.log", file=sys.stderr)
    if doc["run"]["failed_agents"]:
        print(f"failed agents: {doc['run']['failed_agents']}", file=sys.stderr)
    if args.json:
        print(json.dumps(doc, default=_json_default))
    else:
        for k, v in doc["metrics"].items():
            print(f"{k:24s} {v}")
    return 0
