"""Scoring a distributed run: the recorder's rows as the in-process runner's
:class:`~gcs.report.metrics.Series`, the metrics (the same function as in process), the run
document, and the default run directory. Used by :mod:`gcs.mission.distributed` (final write and the
aborted/checkpoint writes)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from gcs.mission.recorder import Recorder
from gcs.mission.run_output import (
    empty_series,
    formation_yaw,
    run_dir_inside,
    run_document,
    run_mission_metrics,
    safety_spec,
    set_truth_rows,
)
from gcs.records.series import RunSeries, rows_of
from gcs.report.metrics import Series, compute_metrics
from offboard.agent.takeoff import is_ground_start, takeoff_plan
from offboard.estimation.bearing import Formation, formation_from_scenario
from swarm_common.scenario.model import Scenario
from vehicle_sim.physics.dynamics import SwarmDynamics


def recorder_series(rec: Recorder, sc: Scenario, steps: np.ndarray | None = None,
                    form: Formation | None = None) -> RunSeries:
    """The recorded run as the in-process runner's :class:`~gcs.report.metrics.Series`.

    Row k holds truth(k), the estimates valid at t_k (published at step k−1), the
    statuses of step k and the minimum pair distance over (t_k, t_k+1] (carried by
    truth(k+1)). Rows use the float32 values that crossed the wire, as in-process.
    ``steps``: only those (steps with a truth, increasing; the live view's latest rows),
    as the recorder holds them now; default: every step with a truth, after a drain.
    ``form``: the scenario's formation, when the caller has it.
    """
    if steps is None:
        rec.drain()
        steps = np.flatnonzero(rec.have_truth[: rec.steps])
    form = formation_from_scenario(sc) if form is None else form
    ser = empty_series(rec.t[steps].copy(), sc.n, fill=np.nan)
    p, v = rec.p[steps].astype(float), rec.v[steps].astype(float)
    set_truth_rows(ser, form, p, v, rec.lumped_true[steps].astype(float),
                   rec.thrust[steps].astype(float), rec.att[steps].astype(float),
                   formation_yaw(sc, p, v))
    nxt = steps + 1
    ser.min_dist[:] = np.where(rec.have_truth[nxt], rec.min_dist[nxt], np.nan)
    ser.z1[:], ser.z2[:] = rec.z1[steps], rec.z2[steps]  # estimates valid at t_k
    ser.xi_p[:] = rec.xi_p[steps]
    ser.u[:], ser.lumped_est[:] = rec.u[steps], rec.lumped_est[steps]
    ser.h_min[:], ser.solve_us[:] = rec.h_min[steps], rec.solve_us[steps]
    ser.fallback[:], ser.input_clipped[:] = rec.degraded[steps], rec.clipped[steps]
    ser.alarms[:] = rec.alarms[steps]
    ser.qp_status[:], ser.qp_active[:] = rec.qp_status[steps], rec.qp_active[steps]
    ser.qp_kinds[:], ser.clf_slack[:] = rec.qp_kinds[steps], rec.clf_slack[steps]
    ser.qp_relax[:], ser.u_nom[:] = rec.qp_relax[steps], rec.u_nom[steps]
    ser.u_corr[:] = rec.u_corr[steps]
    # Real time: an agent may skip a stamp (late cycle), leaving a row without its
    # message; hold the last value (lockstep runs have none missing).
    for arr in (ser.z1, ser.z2, ser.xi_p, ser.u, ser.lumped_est, ser.h_min, ser.solve_us):
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
    truth = rec.truth
    last = truth[max(truth)] if len(truth) else None
    zeta_true = SwarmDynamics(sc, seed=rec.seed).zeta  # the simulator's seeded draw of ζ
    zeta_est = rec.zeta_last.copy()
    fallbacks = sum(st.fallbacks for st in rec.last_status.values())
    valid = ~np.isnan(ser.min_dist)
    if not np.all(valid):  # a run cut short: drop the incomplete tail
        ser = rows_of(ser, valid)
    metrics = compute_metrics(
        ser, form.follower_idx, sc.control_dt, veh.mass_kg, veh.gravity_mps2,
        last.collisions if last else 0, zeta_true, zeta_est, fallbacks, wall_s, duration,
        dataclasses.replace(safety_spec(sc, bool(rec.last_status)),
                            fence_changes=tuple(rec.fence_changes)),
        takeoff_end_s=takeoff_plan(sc).t_blend if is_ground_start(sc) else None,
        land_at_s=land_at, extra=run_mission_metrics(sc, ser, form),
    )
    return metrics, ser


def default_out_dir(sc: Scenario, method: str, parent: Path = Path("runs")) -> Path:
    """``runs/<scenario>-<method>-<time>``, always inside ``parent``."""
    return run_dir_inside(parent, f"{sc.name}-{method}-{time.strftime('%Y%m%d-%H%M%S')}")


def score_run(
    rec: Recorder, sc: Scenario, facts: dict[str, Any], method: str, seed: int | None,
    realtime: bool, land_at: float | None, duration: float,
) -> tuple[dict[str, Any], Series]:
    """The run document and series of what was recorded (possibly a part of the run)."""
    if len(rec.truth) >= 2:
        metrics, ser = recorded_metrics(rec, sc, facts.get("wall_s", 0.0), duration, land_at)
    else:  # stopped before the second step: nothing to score
        metrics, ser = {}, empty_series(np.zeros(0), sc.n)
    run = {k: v for k, v in facts.items() if k != "preflight"}  # top level, as in process
    doc = run_document(
        sc.name, method, sc.seed if seed is None else seed, metrics,
        mode="realtime" if realtime else "lockstep", aborted=bool(facts.get("aborted")),
        run=run, preflight=list(facts.get("preflight") or []),
    )
    return doc, ser


def late_steps(doc: dict[str, Any]) -> int:
    """The simulator's lockstep timeouts in a run's document (0 when it has none)."""
    sim = doc.get("run", {}).get("simulator") or {}
    return int(sim.get("lockstep_timeouts") or 0)


def lockstep_misses(run: dict[str, Any]) -> list[str]:
    """What a lockstep run's facts (``doc["run"]``) report of the waits it gave up, one
    line each: the simulator's lockstep timeouts (a step taken without every answer) and
    the daemons' lockstep gaps (a step taken without a neighbour's estimate or odometry,
    or without its truth; :func:`gcs.mission.run_logs.lockstep_gaps`). Equality with the
    in-process run is promised only when this is empty (docs/architecture.md)."""
    out = []
    timeouts = late_steps({"run": run})
    if timeouts:
        out.append(f"simulator: {timeouts} lockstep timeout(s)")
    gaps = run.get("lockstep_gaps") or {}
    if int(gaps.get("count") or 0):
        out.append(f"daemons: {int(gaps['count'])} lockstep gap(s)")
        out += [f"agent {g['agent']}: no {g['kind']}"
                + (f" of {g['neighbour']}" if g["kind"] != "truth" else "")
                + f" at step {g['step']}" for g in gaps.get("first") or []]
    return out
