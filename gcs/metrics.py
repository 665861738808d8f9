"""Mission metrics from the in-process (or replayed) time series (paper §5; Departure 15).

Energies are over the followers (the methods differ only there):
``energy_u = ∫Σ‖u_i‖²dt``, ``energy_thrust = ∫ΣF_i²dt`` and
``energy_thrust_excess = ∫Σ(F_i − m g)²dt`` (Departure 15: ∫F² is dominated by hover).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

METRIC_KEYS = (
    "min_distance_m",
    "collisions",
    "energy_u",
    "energy_thrust",
    "energy_thrust_excess",
    "formation_time_s",
    "tracking_rms_m",
    "tracking_max_m",
    "est_pos_max_m",
    "est_vel_max_mps",
    "est_dist_max_mps2",
    "zeta_rel_err",
    "max_tilt_deg",
    "max_thrust_n",
    "qp_fallbacks",
    "wall_s",
    "realtime_factor",
)


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
    lumped_est: np.ndarray  # (K,N,3) z3 + Φζ̂ used at t_k
    lumped_true: np.ndarray  # (K,N,3) Φζ + d/m at t_k
    u: np.ndarray  # (K,N,3) virtual control commanded
    thrust: np.ndarray  # (K,N) actual thrust (N)
    tilt_deg: np.ndarray  # (K,N) actual tilt
    min_dist: np.ndarray  # (K,) min pair distance over the period following t_k
    h_min: np.ndarray  # (K,N)
    solve_us: np.ndarray  # (K,N)
    fallback: np.ndarray  # (K,N) bool

    def as_dict(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def formation_time(t: np.ndarray, err: np.ndarray, tol: float = 0.1) -> float | None:
    """First time after which every follower stays within ``tol`` (err: (K,F) norms)."""
    bad = np.any(err >= tol, axis=1)
    if bad[-1]:
        return None
    idx = np.nonzero(bad)[0]
    return float(t[0]) if len(idx) == 0 else float(t[idx[-1] + 1])


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
    est_after_s: float = 5.0,
) -> dict[str, float | int | None]:
    """The metrics dict (keys :data:`METRIC_KEYS`)."""
    f = follower_idx
    err = np.linalg.norm(s.p[:, f] - s.p_des[:, f], axis=2)
    tf = formation_time(s.t, err)
    after = s.t >= (tf if tf is not None else s.t[-1] + 1.0)
    trk_rms: float | None = None
    trk_max: float | None = None
    if np.any(after):
        trk_rms = float(np.sqrt(np.mean(err[after] ** 2)))
        trk_max = float(err[after].max())
    late = s.t >= est_after_s
    ep = np.linalg.norm(s.z1[late][:, f] - s.p[late][:, f], axis=2)
    ev = np.linalg.norm(s.z2[late][:, f] - s.v[late][:, f], axis=2)
    ed = np.linalg.norm(s.lumped_est[late][:, f] - s.lumped_true[late][:, f], axis=2)
    zt = zeta_true[f]
    ze = zeta_est[f]
    zrel = float(np.mean(np.linalg.norm(ze - zt, axis=1) / np.linalg.norm(zt, axis=1)))
    thr = s.thrust[:, f]
    return {
        "min_distance_m": float(s.min_dist.min()),
        "collisions": int(collisions),
        "energy_u": float(np.sum(s.u[:, f] ** 2) * dt),
        "energy_thrust": float(np.sum(thr**2) * dt),
        "energy_thrust_excess": float(np.sum((thr - mass * g) ** 2) * dt),
        "formation_time_s": tf,
        "tracking_rms_m": trk_rms,
        "tracking_max_m": trk_max,
        "est_pos_max_m": float(ep.max()) if ep.size else None,
        "est_vel_max_mps": float(ev.max()) if ev.size else None,
        "est_dist_max_mps2": float(ed.max()) if ed.size else None,
        "zeta_rel_err": zrel,
        "max_tilt_deg": float(s.tilt_deg.max()),
        "max_thrust_n": float(s.thrust.max()),
        "qp_fallbacks": int(fallbacks),
        "wall_s": float(wall_s),
        "realtime_factor": float(duration_s / wall_s) if wall_s > 0 else None,
    }
