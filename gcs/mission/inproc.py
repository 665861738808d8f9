"""In-process mission runner: dynamics + all agents in one process, lockstep.

Same order as the distributed run (docs/architecture.md, lockstep), step k:

1. truth(k) = float32(p, v) of the simulator (what the truth message carries);
2. every agent: ``agent.step(k, t_k, truth, neighbours(k−1), comm_ok)`` (in scenario
   order, or in several processes at once: ``workers``, :mod:`gcs.mission.agents.shards`), where
   neighbours are the float32-rounded estimates published at step k−1 (valid for
   t_k), or at step k−1−d with a latency (``communication.delay_s``, d =
   :attr:`Scenario.delay_periods`, in process only); during an outage window
   (``communication.outages_s``) comm_ok is False;
3. each setpoint goes through the wire form (float32 quaternion + thrust_norm) and is
   decoded exactly as the simulator does (:func:`~gcs.mission.agents.wire_form.wire_to_command`,
   for all agents at once :func:`~gcs.mission.agents.wire_form.wire_to_commands`) →
   ``set_command`` (``set_commands``);
4. the dynamics advance one control period (physics_hz/control_hz physics steps).

Everything that would cross a wire is rounded to float32 (:mod:`gcs.mission.agents.wire_form`),
so a distributed run can reproduce this one bit for bit.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gcs.mission.agents.shards import AgentSteps, agent_steppers
from gcs.mission.agents.wire_form import f32, wire_to_commands
from gcs.mission.audit import audit_document, zenoh_record
from gcs.mission.preflight import warn_liveness
from gcs.mission.progress import Progress
from gcs.mission.run_output import (
    AgentRows,
    empty_series,
    formation_yaw,
    run_document,
    run_mission_metrics,
    safety_spec,
    set_truth_rows,
    warn_verdict,
    write_run,
)
from gcs.records.series import RunSeries
from gcs.report.metrics import Series, compute_metrics
from offboard.agent.landing import landing_plan
from offboard.agent.takeoff import is_ground_start, takeoff_plan
from offboard.estimation.bearing import Formation, formation_from_scenario
from offboard.estimation.peer_table import XI_COL, EstimateBatch
from swarm_common import wire
from swarm_common.blas import single_thread_blas
from swarm_common.enums import CommandKind
from swarm_common.process_life import frozen_while
from swarm_common.scenario.model import Scenario
from vehicle_sim.physics.dynamics import SwarmDynamics

if TYPE_CHECKING:
    from gcs.records.live import LiveView

log = logging.getLogger(__name__)


def in_outage(t: float, outages: tuple[tuple[float, float], ...]) -> bool:
    return any(a <= t < b for a, b in outages)


@dataclass
class MissionResult:
    scenario: str
    method: str
    seed: int
    metrics: dict[str, Any]
    series: Series
    gains: list[str] = field(default_factory=list)
    collision_pairs: list[Any] = field(default_factory=list)
    # the scripted commands, as the distributed runner's audit (gcs.mission.audit)
    audit: dict[str, Any] = field(default_factory=lambda: audit_document(None, []))
    # what the run was warned of before it started (gcs.mission.preflight.warn_liveness)
    preflight: list[str] = field(default_factory=list)

    def document(self) -> dict[str, Any]:
        """The run's ``metrics.json`` document (:func:`gcs.mission.run_output.run_document`)."""
        return run_document(
            self.scenario, self.method, self.seed, self.metrics, gains=self.gains,
            collision_pairs=[list(map(float, c)) for c in self.collision_pairs],
            audit=self.audit, preflight=list(self.preflight),
        )

    def save(self, out_dir: str | Path, sc: Scenario | None = None) -> None:
        """Write metrics.json and series.npz to ``out_dir`` (and, given the run's scenario
        ``sc``, its record.mcap)."""
        write_run(Path(out_dir), self.document(), self.series, sc)


def run_inproc(
    sc: Scenario,
    method: str | None = None,
    seed: int | None = None,
    duration: float | None = None,
    progress: bool = False,
    land_at: float | None = None,
    live: LiveView | None = None,
    workers: int = 1,
) -> MissionResult:
    """Run a mission in process and return its metrics and time series.

    ``progress``: log the gains and show a :class:`~gcs.mission.progress.Progress` on stderr.
    ``land_at``: mission time (s) of a coordinated land-all (offboard.agent.landing,
    docs/lifecycle.md): from the first step at or after it every agent tracks its landing
    reference, the safety filter still active. ``live``: a live view fed the rows while a
    client watches it (:class:`gcs.mission.live_feed.InprocFeed`). ``workers``: processes
    that step the agents, this one included (:mod:`gcs.mission.agents.shards`; the same bits for
    any count).
    """
    seed = sc.seed if seed is None else int(seed)
    method = str(method or sc.controller.method)
    dur = float(sc.run.duration_s if duration is None else duration)
    if sc.faults.active:
        log.warning("%s: the in-process runner has no links, so the scenario's [faults] table "
                    "is NOT applied (a distributed run applies it; docs/faults.md)", sc.name)
    if land_at is None and sc.lifecycle.land_at_s > 0.0:
        land_at = sc.lifecycle.land_at_s
    # tiny matrices only: BLAS worker threads cost, never help (swarm_common.blas); the
    # formation's leader map is computed in here, first by the preflight checks
    with single_thread_blas():
        form = formation_from_scenario(sc)
        preflight = warn_liveness(sc, method, form)
        dyn = SwarmDynamics(sc, seed=seed)
        agents = agent_steppers(sc, method, seed, form, workers)
        try:
            ser, gains, scripted, wall = _fly(sc, method, dur, progress, land_at, live, form,
                                              dyn, agents)
            zeta_est, fallbacks = agents.finish()
        finally:
            agents.close()
    veh = sc.vehicle
    metrics = compute_metrics(
        ser, form.follower_idx, sc.control_dt, veh.mass_kg, veh.gravity_mps2, dyn.collisions,
        dyn.zeta, zeta_est, fallbacks, wall, dur, safety_spec(sc),
        takeoff_end_s=takeoff_plan(sc).t_blend if is_ground_start(sc) else None,
        land_at_s=land_at, extra=run_mission_metrics(sc, ser, form),
    )
    warn_verdict(sc.name, str(method), metrics)
    return MissionResult(
        scenario=sc.name, method=method, seed=seed, metrics=metrics, series=ser, gains=gains,
        collision_pairs=list(dyn.collision_pairs), audit=audit_document(None, scripted),
        preflight=preflight,
    )


def _fly(sc: Scenario, method: str, dur: float, progress: bool, land_at: float | None,
         live: LiveView | None, form: Formation, dyn: SwarmDynamics, agents: AgentSteps,
         ) -> tuple[RunSeries, list[str], list[dict[str, Any]], float]:
    """:func:`run_inproc`'s loop: (series, gains, audit records of the scripted commands,
    wall time of the loop (s))."""
    dt = sc.control_dt
    n_steps = int(round(dur / dt))
    nsub = sc.substeps_per_control
    f_max = sc.vehicle.thrust_max_n
    gains = agents.gains()
    bar = Progress(dur, label=method) if progress else None
    if progress:
        for line in gains:
            log.info("%s", line)
    # every agent's estimate of the step before, as the receivers see it; each follower
    # takes its peers' rows only, as its daemon subscribes to them only
    published = agents.initial()
    # what the agents receive: the batch published delay_periods steps before the last
    # (communication.delay_s; the initial estimates until then)
    in_flight: deque[EstimateBatch] = deque([published], maxlen=sc.delay_periods + 1)
    n = sc.n
    ser = empty_series(np.arange(n_steps) * dt, n)
    # the truth of every step, its derived rows (desired states, tilt) filled after
    # the loop in one product each (gcs.mission.run_output.set_truth_rows)
    lumped_true, thrust, att = (np.zeros((n_steps, n, 3)), np.zeros((n_steps, n)),
                                np.zeros((n_steps, n, 3)))
    md_run = math.inf
    shown = None
    if live is not None:  # its imports (the recorder's Zenoh) only for a live run
        from gcs.mission.live_feed import InprocFeed

        shown = InprocFeed(sc, form, live)
    # the agents' rows written in blocks, or one by one for a live view, which reads
    # each (gcs.mission.run_output.AgentRows)
    agent_rows = AgentRows(ser, n, block=None if shown is None else 1)
    scripted: list[dict[str, Any]] = []  # audit records of the scripted commands
    t_wall = time.perf_counter()
    # collections in the loop skip the set-up (swarm_common.process_life.frozen_while)
    with frozen_while():
        for k in range(n_steps):
            t = k * dt
            if land_at is not None and t >= land_at and not agents.landing_started:
                # t_L = land_at, as in offboard.daemon.commands
                plan = landing_plan(sc, land_at, form)
                log.info("land-all at t=%.2f s (transit %.2f s)", land_at, plan.t_h)
                scripted.append(zenoh_record(
                    t, wire.key_cmd(sc.name, CommandKind.LAND),
                    wire.Command(kind=CommandKind.LAND, at_s=float(land_at))))
                agents.start_landing(plan)
            tp, tv = f32(dyn.p), f32(dyn.v)
            comm = not in_outage(t, sc.outages)
            ser.p[k], ser.v[k], lumped_true[k] = dyn.p, dyn.v, dyn.lumped_accel()
            thrust[k], att[k] = dyn.thrust, dyn.att
            ser.z1[k], ser.z2[k] = published.rows[:, 0:3], published.rows[:, 3:6]
            ser.xi_p[k] = published.rows[:, XI_COL:XI_COL + 3]
            heard = in_flight[0]
            # the commands, estimates and records of all agents at once (each agent's
            # step reads the estimates of the step before and never the dynamics)
            res = agents.step(k, t, tp, tv, heard, comm)
            dyn.set_commands(*wire_to_commands(res.q_ned, res.thrust_norm, f_max))
            published = res.published
            in_flight.append(published)
            agent_rows.add(k, res.rows)
            md = dyn.advance_period(nsub)  # nsub physics steps, their min pair distance
            ser.min_dist[k] = md
            md_run = min(md_run, md)
            if shown is not None:
                shown.step(k, ser, lumped_true, thrust, att, last=k == n_steps - 1)
            if bar is not None:
                bar.update((k + 1) * dt, f"min dist {md_run:.3f} m")
    agent_rows.flush()
    if bar is not None:
        bar.close()
    set_truth_rows(ser, form, ser.p, ser.v, lumped_true, thrust, att,
                   formation_yaw(sc, ser.p, ser.v))
    wall = time.perf_counter() - t_wall
    return ser, gains, scripted, wall
