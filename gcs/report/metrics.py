"""Mission metrics from the in-process (or replayed) time series (paper §5; Departure 15).

Every metric is defined, with its unit and window, in docs/metrics.md. In short:

* safety, from the simulator's TRUE states: ``min_distance_m`` (also per phase), the true
  barrier ``h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D²`` (paper eq. 9, τ = ``tau_safe_s``,
  D = ``d_safe_m``) over every pair and step (:func:`gcs.report.verdict.pair_barrier`),
  and the steps where it is negative;
* tracking, over the FIXED window [``formation_deadline_s``, end] of the followers'
  ‖p − p_des‖ (:func:`window_tracking`), unconditionally;
* energies over the followers (the methods differ only there): ``energy_u = ∫Σ‖u_i‖²dt``,
  ``energy_thrust = ∫ΣF_i²dt`` and ``energy_thrust_excess = ∫Σ(F_i − m g)²dt``
  (Departure 15: ∫F² is dominated by hover).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from gcs.report.verdict import ground_strike_steps, verdict_metrics
from gcs.report.world_metrics import (
    WORLD_KEYS,
    FenceChange,
    world_metric_values,
    world_truth,
)
from swarm_common.world.config import World

if TYPE_CHECKING:  # compiled: imported where a run is scored, not by every CLI
    from gcs.report.pair_barriers import PairBarrierSummary

METRIC_KEYS = (
    "min_distance_m",
    "min_distance_by_phase_m",
    "h_min",
    "barrier_violation_steps",
    "barrier_violation_pair_steps",
    "collisions",
    "ground_strikes",
    # the safety verdict (gcs.report.verdict; docs/metrics.md, "Safety verdict")
    "own_h_min",
    "safety_verdict",
    "safety_alarm_count",
    "deadlock_events",
    "safety_alarms",
    "input_clipped_steps",
    "energy_u",
    "energy_thrust",
    "energy_thrust_excess",
    "formation_time_s",
    "tracking_rms_m",
    "tracking_max_m",
    "tracking_time_above_0p1_s",
    "est_pos_max_m",
    "est_vel_max_mps",
    "est_dist_max_mps2",
    "ref_est_rms_m",
    "ref_est_max_m",
    "zeta_rel_err",
    "max_tilt_deg",
    "max_thrust_n",
    "qp_fallbacks",
    "wall_s",
    "realtime_factor",
    # the world's (gcs.report.world_metrics; None without obstacles or a geofence)
    *WORLD_KEYS,
    # a formation mission's (gcs.report.mission_metrics; None without a [mission])
    "mission_completed",
    "mission_time_s",
    "transit_error_rms_m",
    "transit_error_max_m",
)
MISSION_KEYS = METRIC_KEYS[-4:]
LIST_KEYS = ("safety_alarms",)  # a list of events: in metrics.json, not a CSV column
# computed beside compute_metrics from the scenario (gcs.report.mission_metrics), None here
EXTRA_KEYS = ("ref_est_rms_m", "ref_est_max_m", *MISSION_KEYS)
PHASES = ("takeoff", "formation", "mission", "landing")  # keys of min_distance_by_phase_m
TRACK_TOL_M = 0.1  # m, tolerance of formation_time_s and tracking_time_above_0p1_s


@dataclass
class Series:
    """Time series at the control rate; arrays indexed [step, agent, axis] (scenario order)."""

    t: np.ndarray  # (K,)
    p: np.ndarray  # (K,N,3) true positions at t_k
    v: np.ndarray
    p_des: np.ndarray  # (K,N,3) desired positions from the leaders' true positions
    v_des: np.ndarray
    z1: np.ndarray  # (K,N,3) estimates valid at t_k (published at k−1); leaders: NaN-free copy
    z2: np.ndarray
    xi_p: np.ndarray  # (K,N,3) desired positions estimated, valid at t_k: followers' ξ̂_p
    lumped_est: np.ndarray  # (K,N,3) z3 + Φζ̂ used at t_k
    lumped_true: np.ndarray  # (K,N,3) Φζ + d/m at t_k
    u: np.ndarray  # (K,N,3) virtual control commanded
    thrust: np.ndarray  # (K,N) actual thrust (N)
    tilt_deg: np.ndarray  # (K,N) actual tilt
    min_dist: np.ndarray  # (K,) min pair distance over the period following t_k
    h_min: np.ndarray  # (K,N) smallest barrier value as the agent computed it (its estimates)
    solve_us: np.ndarray  # (K,N)
    fallback: np.ndarray  # (K,N) bool
    input_clipped: np.ndarray  # (K,N) bool: the setpoint conversion changed the commanded u
    alarms: np.ndarray  # (K,N) uint8 AgentAlarm bits the agent raised at t_k

    def as_dict(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def formation_time(t: np.ndarray, err: np.ndarray, tol: float = TRACK_TOL_M) -> float | None:
    """First time after which every follower stays within ``tol`` until the end of the run
    (err: (K,F) norms, m); None when some follower is out of tolerance at the last step."""
    bad = np.any(err >= tol, axis=1)
    if bad[-1]:
        return None
    idx = np.nonzero(bad)[0]
    return float(t[0]) if len(idx) == 0 else float(t[idx[-1] + 1])


def barrier_metrics(
    p: np.ndarray, v: np.ndarray, tau: float, d_safe: float,
    pairs: PairBarrierSummary | None = None,
) -> dict[str, float | int | None]:
    """``h_min`` (m², min of :func:`~gcs.report.verdict.pair_barrier` over pairs and steps),
    the steps where some pair has h < 0 (``barrier_violation_steps``) and the (pair, step)
    samples with h < 0 (``barrier_violation_pair_steps``). ``pairs``: their summary when the
    caller has it already (:func:`~gcs.report.pair_barriers.pair_barrier_summary`)."""
    if p.shape[0] == 0 or p.shape[1] < 2:
        return {"h_min": None, "barrier_violation_steps": 0, "barrier_violation_pair_steps": 0}
    if pairs is None:
        from gcs.report.pair_barriers import pair_barrier_summary

        pairs = pair_barrier_summary(p, v, tau, d_safe)
    return {
        "h_min": pairs.h_min,
        "barrier_violation_steps": pairs.violation_steps,
        "barrier_violation_pair_steps": pairs.violation_pair_steps,
    }


def window_tracking(
    t: np.ndarray, err: np.ndarray, t0: float, dt: float, tol: float = TRACK_TOL_M
) -> dict[str, float | None]:
    """Tracking over the fixed window t ≥ ``t0`` (s), whatever happened in it.

    ``err``: (K,F) follower errors ‖p − p_des‖ (m). Returns ``tracking_rms_m`` (RMS over
    every follower-step of the window), ``tracking_max_m`` and
    ``tracking_time_above_0p1_s`` (steps × ``dt`` where any follower's error > ``tol``);
    all None when no step reaches ``t0`` (a run shorter than the deadline).
    """
    w = t >= t0 - 1e-9
    if not np.any(w) or err.shape[1] == 0:
        return {"tracking_rms_m": None, "tracking_max_m": None,
                "tracking_time_above_0p1_s": None}
    e = err[w]
    return {
        "tracking_rms_m": float(np.sqrt(np.mean(e**2))),
        "tracking_max_m": float(e.max()),
        "tracking_time_above_0p1_s": float(np.sum(np.any(e > tol, axis=1)) * dt),
    }


def min_distance_by_phase(
    t: np.ndarray, min_dist: np.ndarray, deadline_s: float,
    takeoff_end_s: float | None = None, land_at_s: float | None = None,
) -> dict[str, float | None]:
    """Smallest pair distance (m) per phase (keys :data:`PHASES`): "takeoff" t < takeoff_end_s
    (ground starts, docs/lifecycle.md; else None), "formation" from then to the deadline,
    "mission" from the deadline to ``land_at_s`` (or the end), "landing" t ≥ land_at_s (None
    without a land-all); a phase without steps is None."""

    def mn(mask: np.ndarray) -> float | None:
        return float(min_dist[mask].min()) if np.any(mask) else None

    eps = 1e-9
    takeoff = t < takeoff_end_s - eps if takeoff_end_s is not None else np.zeros(len(t), bool)
    landing = t >= land_at_s - eps if land_at_s is not None else np.zeros(len(t), bool)
    mission = (t >= deadline_s - eps) & ~landing
    formation = ~takeoff & ~mission & ~landing
    return {
        "takeoff": mn(takeoff) if takeoff_end_s is not None else None,
        "formation": mn(formation),
        "mission": mn(mission),
        "landing": mn(landing) if land_at_s is not None else None,
    }


@dataclass(frozen=True)
class SafetySpec:
    """What the safety and tracking metrics are measured against (from the scenario)."""

    tau_safe_s: float  # s, barrier horizon τ
    d_safe_m: float  # m, barrier distance D
    formation_deadline_s: float  # s, start of the tracking window and of phase "mission"
    clipped_known: bool = True  # False: the statuses did not carry input_clipped
    ids: tuple[int, ...] = ()  # the agents' ids in column order (the verdict's events name them)
    collision_radius_m: float = 0.0  # m, a pair closer than this is in contact
    world: World = field(default_factory=World)  # obstacles and geofence (docs/world.md)
    # κ of the pair barrier (controller.dcbf_vertical_scale, docs/safety.md §4c): the
    # scenario's safe set, the same for every method flown in it; 1 = the sphere
    vertical_scale: float = 1.0
    # the vehicles' stored fences as a ground station changed them in a distributed run
    # (gcs.report.world_metrics.FenceChange): scored from then instead of the scenario's
    fence_changes: tuple[FenceChange, ...] = ()


def ground_strikes(p: np.ndarray, v: np.ndarray) -> int:
    """Touchdowns faster than a landing (:func:`gcs.report.verdict.ground_strike_steps`)."""
    return len(ground_strike_steps(p, v)[0])


def compute_metrics(
    s: Series,
    follower_idx: list[int],
    dt: float,
    mass: float,
    g: float,
    collisions: int,
    zeta_true: np.ndarray,
    zeta_est: np.ndarray,
    fallbacks: int,
    wall_s: float,
    duration_s: float,
    spec: SafetySpec,
    est_after_s: float = 5.0,
    takeoff_end_s: float | None = None,
    land_at_s: float | None = None,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The metrics dict (keys :data:`METRIC_KEYS`; definitions in docs/metrics.md).
    ``takeoff_end_s`` / ``land_at_s`` (s): phase bounds of ``min_distance_by_phase_m``;
    ``extra``: the keys of :data:`EXTRA_KEYS` computed from the scenario (the desired-state
    observer's error, the formation mission's; :mod:`gcs.report.mission_metrics`), None
    each when not given."""
    f = follower_idx
    # formation tracking ends where the land-all begins (the landing reference is not the
    # formation): the window is [deadline, land_at_s), fixed before the run
    flying = s.t < land_at_s - 1e-9 if land_at_s is not None else np.ones(len(s.t), bool)
    err = np.linalg.norm(s.p[flying][:, f] - s.p_des[flying][:, f], axis=2)
    t_fly = s.t[flying]
    late = s.t >= est_after_s
    ep = np.linalg.norm(s.z1[late][:, f] - s.p[late][:, f], axis=2)
    ev = np.linalg.norm(s.z2[late][:, f] - s.v[late][:, f], axis=2)
    ed = np.linalg.norm(s.lumped_est[late][:, f] - s.lumped_true[late][:, f], axis=2)
    zt = zeta_true[f]
    ze = zeta_est[f]
    zrel = float(np.mean(np.linalg.norm(ze - zt, axis=1) / np.linalg.norm(zt, axis=1)))
    thr = s.thrust[:, f]
    deadline = spec.formation_deadline_s
    # the true barrier of every pair and step, once: the barrier metrics and the verdict
    from gcs.report.pair_barriers import pair_barrier_summary

    h = (pair_barrier_summary(s.p, s.v, spec.tau_safe_s, spec.d_safe_m, spec.vertical_scale)
         if s.p.shape[1] >= 2 and len(s.t) else None)
    world = world_truth(spec.world, s.p, s.v, spec.tau_safe_s, s.t, spec.fence_changes,
                        spec.d_safe_m)
    return {
        "min_distance_m": float(s.min_dist.min()),
        "min_distance_by_phase_m": min_distance_by_phase(
            s.t, s.min_dist, deadline, takeoff_end_s, land_at_s
        ),
        **barrier_metrics(s.p, s.v, spec.tau_safe_s, spec.d_safe_m, h),
        "collisions": int(collisions),
        "ground_strikes": ground_strikes(s.p, s.v),
        **verdict_metrics(
            s.t, s.p, s.v, s.min_dist, s.h_min, s.alarms,
            list(spec.ids) or list(range(s.p.shape[1])), f, spec.tau_safe_s, spec.d_safe_m,
            spec.collision_radius_m, h, world,
        ),
        "input_clipped_steps": int(np.sum(s.input_clipped)) if spec.clipped_known else None,
        "energy_u": float(np.sum(s.u[:, f] ** 2) * dt),
        "energy_thrust": float(np.sum(thr**2) * dt),
        "energy_thrust_excess": float(np.sum((thr - mass * g) ** 2) * dt),
        "formation_time_s": formation_time(t_fly, err) if len(t_fly) else None,
        **window_tracking(t_fly, err, deadline, dt),
        "est_pos_max_m": float(ep.max()) if ep.size else None,
        "est_vel_max_mps": float(ev.max()) if ev.size else None,
        "est_dist_max_mps2": float(ed.max()) if ed.size else None,
        "ref_est_rms_m": None,
        "ref_est_max_m": None,
        "zeta_rel_err": zrel,
        "max_tilt_deg": float(s.tilt_deg.max()),
        "max_thrust_n": float(s.thrust.max()),
        "qp_fallbacks": int(fallbacks),
        "wall_s": float(wall_s),
        "realtime_factor": float(duration_s / wall_s) if wall_s > 0 else None,
        **world_metric_values(world),
        **dict.fromkeys(MISSION_KEYS),
    } | (extra or {})  # a union keeps the keys' order
