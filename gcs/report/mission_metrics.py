"""Metrics of a formation mission (docs/missions.md, docs/metrics.md).

* ``mission_completed``: the formation's centroid (the mean of every agent's TRUE position)
  came within the mission's ``arrive_radius_m`` of each waypoint's centroid, in order, during
  the run;
* ``mission_time_s``: the run time at which it reached the last one (None when it did not);
* ``transit_error_rms_m``, ``transit_error_max_m``: the followers' formation error
  ‖p − p_des‖ (the tracking metrics' error: desired positions from the leaders' true
  positions) over every step of the fixed transit window, from the plan's departure from
  the first waypoint to its arrival at the last (:attr:`MissionPlan.transit_window`).

Every key is None for a scenario without a mission. The mission clock is the run's clock:
a lockstep or in-process run starts its mission at t = 0.

Desired positions of a turned formation (:func:`yawed_desired`): the bearings turn with the
formation's yaw ψ, read from the leaders' offset as the followers read it
(:mod:`offboard.estimation.formation_frame`): p_des = R D₀(Rᵀ p_L), with D₀ the fixed-bearing
map of :meth:`Formation.desired_positions_series`, and its derivative
v_des = ψ' J p_des + R D₀(Rᵀ(v_L − ψ' J p_L)) (J the 90° turn about z).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gcs.report.metrics import MISSION_KEYS
from offboard.estimation.bearing import Formation
from swarm_common.scenario.mission_check import plan_for, yaw_leaders, yaws
from swarm_common.scenario.spec import Scenario


def leader_yaw(sc: Scenario, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ψ (K,) rad, ψ' (K,) rad/s) of the formation from K rows of every agent's position and
    velocity (K,N,3): the first two leaders' horizontal offset against the mission's shape."""
    a, b, offset = yaw_leaders(sc)
    r0 = complex(*offset[:2])
    r = (p[:, b, 0] - p[:, a, 0]) + 1j * (p[:, b, 1] - p[:, a, 1])
    rd = (v[:, b, 0] - v[:, a, 0]) + 1j * (v[:, b, 1] - v[:, a, 1])
    return np.angle(r / r0), (rd / r).imag


def _turn(x: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """(K,M,3) turned by ψ (K,) about z."""
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    out = x.copy()
    out[..., 0] = c * x[..., 0] - s * x[..., 1]
    out[..., 1] = s * x[..., 0] + c * x[..., 1]
    return out


def _j(x: np.ndarray) -> np.ndarray:
    """J x: (x, y, z) → (−y, x, 0)."""
    out = np.zeros_like(x)
    out[..., 0], out[..., 1] = -x[..., 1], x[..., 0]
    return out


def yawed_desired(
    form: Formation, lid: list[int], p: np.ndarray, v: np.ndarray, psi: np.ndarray,
    psi_dot: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(p_des, v_des) (K,N,3) of a formation turned by ψ (module docstring), from every
    agent's rows p, v (K,N,3); ``lid`` the leaders' indices."""
    pl, vl = p[:, lid], v[:, lid]
    p_des = _turn(form.desired_positions_series(_turn(pl, -psi)), psi)
    w = psi_dot[:, None, None]
    v_rel = _turn(form.desired_positions_series(_turn(vl - w * _j(pl), -psi)), psi)
    return p_des, w * _j(p_des) + v_rel


def mission_metrics(
    sc: Scenario, t: np.ndarray, p: np.ndarray, p_des: np.ndarray, follower_idx: list[int],
) -> dict[str, Any]:
    """The :data:`MISSION_KEYS` of a run (module docstring): times ``t`` (K,), every
    agent's true and desired positions (K,N,3)."""
    if sc.mission is None:
        return dict.fromkeys(MISSION_KEYS)
    plan = plan_for(sc)
    radius = sc.mission.arrive_radius_m
    centroid = p.mean(axis=1)
    targets = [np.array(w.centroid) for w in sc.mission.waypoints]
    k, reached_at = 0, None
    for r in range(len(t)):
        if k < len(targets) and np.linalg.norm(centroid[r] - targets[k]) <= radius:
            k += 1
            if k == len(targets):
                reached_at = float(t[r])
                break
    t0, t1 = plan.transit_window
    w = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
    err = np.linalg.norm(p[w][:, follower_idx] - p_des[w][:, follower_idx], axis=2)
    return {
        "mission_completed": reached_at is not None,
        "mission_time_s": reached_at,
        "transit_error_rms_m": float(np.sqrt(np.mean(err**2))) if err.size else None,
        "transit_error_max_m": float(err.max()) if err.size else None,
    }


def observer_metrics(
    sc: Scenario, form: Formation, t: np.ndarray, xi_p: np.ndarray, after_s: float = 5.0,
) -> dict[str, Any]:
    """``ref_est_rms_m``, ``ref_est_max_m``: the followers' desired-state observer error
    ‖ξ̂_p,i − p*_i‖ (m) over every step t ≥ ``after_s`` (the estimate metrics' window), p*
    the formation that the leaders' broadcast reference positions define (turned by their
    yaw for a turning mission): what the observer estimates. ``xi_p`` (K,N,3): every
    agent's ξ̂_p (the leaders' own reference)."""
    late = t >= after_s - 1e-9
    x = xi_p[late]
    f = form.follower_idx
    if not len(x) or not f or not np.all(np.isfinite(x[:, form.leader_idx])):
        return {"ref_est_rms_m": None, "ref_est_max_m": None}
    if yaws(sc):
        psi, _ = leader_yaw(sc, x, np.zeros_like(x))
        want, _ = yawed_desired(form, form.leader_idx, x, np.zeros_like(x), psi,
                                np.zeros_like(psi))
    else:
        want = form.desired_positions_series(x[:, form.leader_idx])
    err = np.linalg.norm(x[:, f] - want[:, f], axis=2)
    return {"ref_est_rms_m": float(np.sqrt(np.mean(err**2))), "ref_est_max_m": float(err.max())}
