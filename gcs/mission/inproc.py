"""In-process mission runner: dynamics + all agents in one process, lockstep.

Same order as the distributed run (docs/architecture.md, lockstep), step k:

1. truth(k) = float32(p, v) of the simulator (what the truth message carries);
2. every agent, in scenario order: ``agent.step(k, t_k, truth, neighbours(k−1), comm_ok)``
   where neighbours are the float32-rounded estimates published at step k−1 (valid for
   t_k), or at step k−1−d with a latency (``communication.delay_s``, d =
   :attr:`Scenario.delay_periods`, in process only); during an outage window
   (``communication.outages_s``) comm_ok is False;
3. each setpoint goes through the wire form (float32 quaternion + thrust_norm) and is
   decoded exactly as the simulator does (:func:`wire_to_command`, for all agents at once
   :func:`wire_to_commands`) → ``set_command`` (``set_commands``);
4. the dynamics advance one control period (physics_hz/control_hz physics steps).

Everything that would cross a wire is rounded to float32 with :func:`f32` /
:func:`round_estimate` (all agents' estimates as one :func:`published_batch`), so a
distributed run can reproduce this one bit for bit.
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
from gcs.report.metrics import Series, compute_metrics
from offboard.agent.factory import FollowerAgent, NeighbourEstimate, make_agent
from offboard.agent.landing import landing_plan
from offboard.agent.takeoff import is_ground_start, takeoff_plan
from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.peer_table import ROW, XI_COL, EstimateBatch
from swarm_common import wire
from swarm_common.blas import single_thread_blas
from swarm_common.enums import CommandKind
from swarm_common.frames import euler_enu_from_quats_ned
from swarm_common.process_life import frozen_while
from swarm_common.scenario.model import Scenario
from vehicle_sim.physics.dynamics import SwarmDynamics

if TYPE_CHECKING:
    from gcs.records.live import LiveView

log = logging.getLogger(__name__)


def f32(x: np.ndarray | float) -> np.ndarray:
    """Round to float32 and back to float64: the value after one trip over the wire.

    Use it on every value that crosses a process boundary (truth p/v, setpoint quaternion
    and thrust_norm, neighbour estimates) in both the in-process and the distributed run.
    """
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def wire_to_command(
    q_ned: np.ndarray, thrust_norm: float | np.floating[Any], thrust_max_n: float
) -> tuple[float, float, float, float]:
    """SET_ATTITUDE_TARGET payload → (roll, pitch, yaw, F) exactly as the simulator does it.

    ``roll, pitch, yaw = euler_enu_from_quat_ned(float32 q)``; ``F = norm_to_thrust(float32
    thrust_norm)``. The simulator's MAVLink side must call this same function.
    """
    roll, pitch, yaw, f = wire_to_commands(
        np.asarray(q_ned, dtype=np.float32).reshape(1, 4),
        np.asarray([thrust_norm], dtype=np.float32), thrust_max_n,
    )
    return float(roll[0]), float(pitch[0]), float(yaw[0]), float(f[0])


def wire_to_commands(
    q_ned: np.ndarray, thrust_norm: np.ndarray, thrust_max_n: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`wire_to_command` of every agent at once: (N,4) float32 quaternions and (N,)
    float32 normalised thrusts → (N,) roll, pitch, yaw (rad), F (N):
    ``euler_enu_from_quat_ned`` of each float32 quaternion (one compiled call) and each
    float32 thrust times F_max (``norm_to_thrust``), as the simulator decodes them."""
    att = euler_enu_from_quats_ned(np.asarray(q_ned, dtype=np.float32))
    f = np.asarray(thrust_norm, dtype=np.float32).astype(np.float64) * thrust_max_n
    return att[:, 0], att[:, 1], att[:, 2], f


def round_estimates(ests: list[NeighbourEstimate]) -> list[NeighbourEstimate]:
    """:func:`round_estimate` of each of ``ests``: the four vectors of all of them rounded
    in one array (the same float32 value per element)."""
    x = _rounded_rows(ests)
    return [NeighbourEstimate(e.id, e.t, r[0:3], r[3:6], r[6:9], r[9:], e.is_leader,
                              e.cooperative)
            for e, r in zip(ests, x, strict=True)]


def round_estimate(e: NeighbourEstimate) -> NeighbourEstimate:
    """A published estimate as the receivers see it (float32 vectors; t kept exact)."""
    return round_estimates([e])[0]


def _rounded_rows(ests: list[NeighbourEstimate]) -> np.ndarray:
    """(len(ests), ROW) [z1, z2, z3, ξ] of each estimate, float32-rounded."""
    x = f32(np.concatenate([v for e in ests for v in (e.z1, e.z2, e.z3, e.xi)]))
    return x.reshape(len(ests), ROW)


def published_batch(ests: list[NeighbourEstimate]) -> EstimateBatch:
    """The estimates of all agents (scenario order) as every receiver sees them: one
    :class:`~offboard.estimation.peer_table.EstimateBatch`, rows as :func:`round_estimates` rounds
    them (t exact). Each row keeps its estimate's ``cooperative`` flag, as the wire does
    (offboard.daemon.wire_convert.put_row): a non-cooperative follower's estimates say so
    from its initial one on, and the others' full shares against it (offboard.agent.shares)
    start at the same step in both runs."""
    return EstimateBatch(
        np.array([e.t for e in ests], dtype=np.float64), _rounded_rows(ests),
        np.array([e.is_leader for e in ests], dtype=np.bool_),
        np.array([e.cooperative for e in ests], dtype=np.bool_),
    )


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
) -> MissionResult:
    """Run a mission in process and return its metrics and time series.

    ``progress``: log the gains and show a :class:`~gcs.mission.progress.Progress` on stderr.
    ``land_at``: mission time (s) of a coordinated land-all (offboard.agent.landing,
    docs/lifecycle.md): from the first step at or after it every agent tracks its landing
    reference, the safety filter still active. ``live``: a live view fed the rows while a
    client watches it (:class:`gcs.mission.live_feed.InprocFeed`).
    """
    seed = sc.seed if seed is None else int(seed)
    method = str(method or sc.controller.method)
    dur = float(sc.run.duration_s if duration is None else duration)
    if sc.faults.active:
        log.warning("%s: the in-process runner has no links, so the scenario's [faults] table "
                    "is NOT applied (a distributed run applies it; docs/faults.md)", sc.name)
    if land_at is None and sc.lifecycle.land_at_s > 0.0:
        land_at = sc.lifecycle.land_at_s
    dt = sc.control_dt
    n_steps = int(round(dur / dt))
    nsub = sc.substeps_per_control
    veh = sc.vehicle
    f_max = veh.thrust_max_n
    # tiny matrices only: BLAS worker threads cost, never help (swarm_common.blas); the
    # formation's leader map is computed in here, first by the preflight checks
    with single_thread_blas():
        form = formation_from_scenario(sc)
        preflight = warn_liveness(sc, method, form)
        dyn = SwarmDynamics(sc, seed=seed)
        agents = [make_agent(sc, a.id, method=method, seed=seed, form=form) for a in sc.agents]
        gains: list[str] = []
        for ag in agents:
            if isinstance(ag, FollowerAgent):
                gains = ag.gains.lines()
                break
        bar = Progress(dur, label=method) if progress else None
        if progress:
            for line in gains:
                log.info("%s", line)
        # every agent's estimate of the step before, as the receivers see it; each follower
        # takes its peers' rows only, as its daemon subscribes to them only
        published = published_batch([ag.initial_estimate() for ag in agents])
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
                if land_at is not None and t >= land_at and agents[0].landing is None:
                    # t_L = land_at, as in offboard.daemon.commands
                    plan = landing_plan(sc, land_at, form)
                    log.info("land-all at t=%.2f s (transit %.2f s)", land_at, plan.t_h)
                    scripted.append(zenoh_record(
                        t, wire.key_cmd(sc.name, CommandKind.LAND),
                        wire.Command(kind=CommandKind.LAND, at_s=float(land_at))))
                    for ag in agents:
                        ag.start_landing(plan)
                tp, tv = f32(dyn.p), f32(dyn.v)
                comm = not in_outage(t, sc.outages)
                ser.p[k], ser.v[k], lumped_true[k] = dyn.p, dyn.v, dyn.lumped_accel()
                thrust[k], att[k] = dyn.thrust, dyn.att
                ser.z1[k], ser.z2[k] = published.rows[:, 0:3], published.rows[:, 3:6]
                ser.xi_p[k] = published.rows[:, XI_COL:XI_COL + 3]
                heard = in_flight[0]
                outs = [ag.step(k, t, tp, tv, heard, comm) for ag in agents]
                # the commands, estimates and records of all agents at once (each agent's
                # step reads the estimates of the step before and never the dynamics)
                dyn.set_commands(*wire_to_commands(
                    np.concatenate([o.q_ned for o in outs]).reshape(n, 4),
                    np.array([o.thrust_norm for o in outs], dtype=np.float32), f_max,
                ))
                published = published_batch([o.estimate for o in outs])
                in_flight.append(published)
                agent_rows.add(k, outs)
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
    zeta_est = np.zeros((n, 6))
    fallbacks = 0
    for i, ag in enumerate(agents):
        if isinstance(ag, FollowerAgent):
            zeta_est[i] = ag.deso.zeta
            fallbacks += ag.fallbacks
    metrics = compute_metrics(
        ser, form.follower_idx, dt, veh.mass_kg, veh.gravity_mps2, dyn.collisions,
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
