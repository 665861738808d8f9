"""Distributed mission runs: ``gcs mission run SCENARIO`` without ``--inproc``.

Starts, as real processes: one ``vehicle-sim`` (lockstep by default) and one
``offboard`` daemon per agent; hosts the Zenoh router itself (clients connect to it);
records every step's truth, estimates and statuses from Zenoh; shows a progress bar
(:mod:`gcs.progress`); stops everything at the end, on Ctrl-C, or when a child dies
(naming it, exit 1). Ports and command lines come from :class:`gcs.launch_spec.LaunchSpec`.

Run directory: ``metrics.json``, ``series.npz`` (:mod:`gcs.run_output`),
``vehicle_<id>.tlog`` (each daemon's MAVLink link, readable by pymavlink's tools) and
one ``<process>.log`` per child.
"""

from __future__ import annotations

import json
import logging
import resource
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from gcs.launch_spec import LaunchError, LaunchSpec
from gcs.metrics import Series, compute_metrics
from gcs.procs import ProcessGroup
from gcs.progress import Progress
from gcs.router import open_router
from gcs.run_output import (
    empty_series,
    print_result,
    run_document,
    safety_spec,
    set_agent_row,
    set_truth_row,
    write_run,
)
from offboard.bearing import formation_from_scenario
from offboard.takeoff import is_ground_start, takeoff_plan
from swarm_common import wire
from swarm_common.scenario import Scenario
from vehicle_sim.dynamics import SwarmDynamics

log = logging.getLogger(__name__)


class MissionError(RuntimeError):
    """A run failed once started: a child died or the run stalled (exit 1). ``str()``
    names the culprit."""


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

    def subscribe(self, session: Any, swarm: str) -> list[Any]:
        """Declare the truth, estimate and status subscribers on ``session``."""
        return [
            session.declare_subscriber(wire.key_truth(swarm), self.on_truth),
            session.declare_subscriber(wire.key_estimate(swarm, "*"), self.on_estimate),
            session.declare_subscriber(wire.key_status(swarm, "*"), self.on_status),
        ]

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
    land_at: float | None = None,
) -> tuple[Recorder, dict[str, Any]]:
    """Run the mission as real processes; return the recorder and run facts.

    ``land_at``: publish a Zenoh land-all command (``wire.Command`` kind "land", at_s =
    land_at) until the run passes that mission time (docs/lifecycle.md).

    Raises :class:`~gcs.launch_spec.LaunchError` before starting anything when a port is
    busy, :class:`MissionError` when a child dies or the run stalls. Every child is
    stopped on the way out, whatever ends the run (Ctrl-C included).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    spec = LaunchSpec(
        sc, port_offset, method=method, seed=seed, lockstep=not realtime, run_dir=out_dir,
        sim_duration=duration + 1.0,
    )
    spec.check_ports()
    try:
        router = open_router([spec.router_endpoint])
    except (RuntimeError, ValueError) as exc:
        raise LaunchError(str(exc)) from None
    steps = int(round(duration * sc.run.control_hz))
    rec = Recorder(sc, steps, seed=seed)
    subs = rec.subscribe(router, spec.swarm_name)
    group = ProcessGroup(out_dir)
    facts: dict[str, Any] = {"failed_agents": [], "killed_agents": []}
    t_wall0 = time.monotonic()
    cpu0 = time.process_time()
    try:
        for name, argv in spec.processes():
            group.start(name, argv)
        bar = Progress(duration, label=str(method)) if show_progress else None
        on_step = None if land_at is None else _land_sender(router, spec.swarm_name, land_at,
                                                             sc.control_dt)
        facts.update(
            _supervise(rec, group, sc.control_dt, kill_agent, kill_at, bar,
                       stall_timeout, out_dir, on_step)
        )
        facts["processes"] = group.usage()
        facts["processes"]["gcs (router + recorder)"] = {
            "cpu_s": time.process_time() - cpu0,
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        }
    finally:
        group.stop()
        for s in subs:
            try:
                s.undeclare()
            except zenoh.ZError as exc:
                log.debug("undeclare subscriber: %s", exc)
        router.close()
        rec.finalize()
    facts["wall_s"] = time.monotonic() - t_wall0
    stats_path = spec.sim_stats_path
    if stats_path is not None and stats_path.exists():
        try:
            facts["simulator"] = json.loads(stats_path.read_text())
        except ValueError as exc:
            log.warning("%s: not JSON (%s); run facts without simulator stats", stats_path, exc)
    facts["failed_agents"] = list(facts["killed_agents"])
    return rec, facts


def _land_sender(session: Any, swarm: str, land_at: float, dt: float) -> Callable[[int], None]:
    """on_step callback: (re)publish the land command every 0.5 s (wall) from step 1 on
    (every agent subscribed) until the run is 1 s past ``land_at``; the daemons keep the
    first one they receive."""
    key = wire.key_cmd(swarm, "land")
    payload = wire.encode(wire.Command(kind="land", at_s=float(land_at)))
    last = [0.0]

    def send(k: int) -> None:
        now = time.monotonic()
        if k >= 1 and k * dt <= land_at + 1.0 and now - last[0] >= 0.5:
            session.put(key, payload)
            last[0] = now

    return send


def _supervise(
    rec: Recorder,
    group: ProcessGroup,
    dt: float,
    kill_agent: int | None,
    kill_at: float | None,
    bar: Progress | None,
    stall_timeout: float,
    out_dir: Path,
    on_step: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Watch a started run until step ``rec.steps``: show progress, kill ``kill_agent``
    at ``kill_at`` (s), raise :class:`MissionError` on a death or a stall. Returns the
    timing facts (``run_wall_s``, ``stepping_wall_s``, ``stepping_realtime_factor``)."""
    facts: dict[str, Any] = {"killed_agents": []}
    victim = None if kill_agent is None else f"offboard-{kill_agent}"
    last_k = -1
    last_change = t_run0 = time.monotonic()
    t_first: float | None = None
    k_first = 0
    try:
        while True:
            time.sleep(0.05)
            with rec.lock:
                k = rec.max_step
            if k >= 1 and t_first is None:
                t_first, k_first = time.monotonic(), k
            if k != last_k:
                last_change, last_k = time.monotonic(), k
                if bar is not None:
                    bar.update(max(k, 0) * dt)
            if k >= rec.steps:
                break
            if on_step is not None:
                on_step(k)
            if victim is not None and not facts["killed_agents"] and k * dt >= (kill_at or 0.0):
                group.kill(victim)
                facts["killed_agents"].append(kill_agent)
            for child in group.dead():
                if child.name == victim and facts["killed_agents"]:
                    continue
                raise MissionError(
                    f"{child.name} exited with code {child.proc.returncode}; "
                    f"last lines of {child.log_path}:\n{group.tail(child)}"
                )
            if time.monotonic() - last_change > stall_timeout:
                raise MissionError(
                    f"run stalled at step {k} for {stall_timeout:.0f} s; see logs in {out_dir}"
                )
    finally:
        if bar is not None:
            bar.close()
    facts["run_wall_s"] = time.monotonic() - t_run0
    if t_first is not None:
        stepping = time.monotonic() - t_first
        facts["stepping_wall_s"] = stepping
        facts["stepping_realtime_factor"] = (rec.steps - k_first) * dt / stepping
    return facts


def recorder_series(rec: Recorder, sc: Scenario) -> Series:
    """The recorded run as the in-process runner's :class:`~gcs.metrics.Series`.

    Row k holds truth(k), the estimates valid at t_k (published at step k−1), the
    statuses of step k and the minimum pair distance over (t_k, t_k+1] (carried by
    truth(k+1)). Rows use the float32 values that crossed the wire, as in-process.
    """
    form = formation_from_scenario(sc)
    steps = [k for k in range(rec.steps) if k in rec.truth]
    idx = {a.id: i for i, a in enumerate(sc.agents)}
    ser = empty_series(np.array([rec.truth[k].t for k in steps]), sc.n, fill=np.nan)
    for r, k in enumerate(steps):
        tr = rec.truth[k]
        set_truth_row(ser, r, form, tr.p, tr.v, tr.lumped, tr.thrust, tr.att)
        nxt = rec.truth.get(k + 1)
        ser.min_dist[r] = nxt.min_dist if nxt is not None else np.nan
        for aid, e in rec.est.get(k - 1, {}).items():
            if aid in idx:
                ser.z1[r, idx[aid]], ser.z2[r, idx[aid]] = e.z1, e.z2
        for aid, st in rec.status.get(k, {}).items():
            if aid in idx:
                set_agent_row(
                    ser, r, idx[aid], st.u, st.lumped, st.h_min, st.qp_solve_us, st.qp_status,
                    st.input_clipped,
                )
    # Real time: an agent may skip a stamp (late cycle), leaving a row without its
    # message; hold the last value (lockstep runs have none missing).
    for arr in (ser.z1, ser.z2, ser.u, ser.lumped_est, ser.h_min, ser.solve_us):
        for r in range(1, len(steps)):
            gap = np.isnan(arr[r])
            if np.any(gap):
                arr[r][gap] = arr[r - 1][gap]
    ser.u[np.isnan(ser.u)] = 0.0  # before a daemon's first status: no command known
    return ser


def recorded_metrics(
    rec: Recorder, sc: Scenario, wall_s: float, duration: float, land_at: float | None = None
) -> tuple[dict[str, Any], Series]:
    """Metrics of a distributed run, computed by the same function as in process
    (``land_at``: the land-all time, s, bounds the "landing" phase)."""
    ser = recorder_series(rec, sc)
    form = formation_from_scenario(sc)
    veh = sc.vehicle
    last = rec.truth[max(rec.truth)] if rec.truth else None
    zeta_true = SwarmDynamics(sc, seed=rec.seed).zeta  # the simulator's seeded draw of ζ
    zeta_est = np.zeros((sc.n, 6))
    for a_id, e in rec.est.get(rec.steps - 1, {}).items():
        zeta_est[sc.index_of(a_id)] = e.zeta
    fallbacks = sum(st.fallbacks for st in rec.last_status.values())
    valid = ~np.isnan(ser.min_dist)
    if not np.all(valid):  # a run cut short: drop the incomplete tail
        ser = Series(**{k: v[valid] for k, v in ser.as_dict().items()})
    metrics = compute_metrics(
        ser, form.follower_idx, sc.control_dt, veh.mass_kg, veh.gravity_mps2,
        last.collisions if last else 0, zeta_true, zeta_est, fallbacks, wall_s, duration,
        safety_spec(sc, bool(rec.last_status)),
        takeoff_end_s=takeoff_plan(sc).t_blend if is_ground_start(sc) else None,
        land_at_s=land_at,
    )
    return metrics, ser


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
    land_at: float | None = None,
) -> dict[str, Any]:
    """One distributed run -> metrics.json + series.npz in ``out_dir``; returns the document."""
    rec, facts = run_distributed(
        sc, out_dir, method, seed, duration, realtime=realtime, port_offset=port_offset,
        kill_agent=kill_agent, kill_at=kill_at, show_progress=show_progress, land_at=land_at,
    )
    metrics, ser = recorded_metrics(rec, sc, facts["wall_s"], duration, land_at)
    doc = run_document(
        sc.name, method, sc.seed if seed is None else seed, metrics,
        mode="realtime" if realtime else "lockstep", run=facts,
    )
    write_run(out_dir, doc, ser)
    return doc


def cli_run(args: Any, sc: Scenario) -> int:
    """``gcs mission run SCENARIO`` (distributed). Exit 2: bad input or a busy port;
    1: a child died or the run stalled (see :mod:`gcs.cli` for the table)."""
    method = str(args.method or sc.controller.method)
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
            show_progress=True, land_at=getattr(args, "land_at", None),
        )
    except LaunchError as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return 2
    except MissionError as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return 1
    log.info("wrote %s/metrics.json, series.npz, vehicle_*.tlog, *.log", out)
    if doc["run"]["failed_agents"]:
        log.warning("failed agents: %s", doc["run"]["failed_agents"])
    print_result(doc, args.json)
    return 0
