"""A run's safety verdict: every broken safety assumption as a timed event, and one word
for the run (docs/metrics.md, "Safety verdict"; docs/safety.md, "Alarms").

The events come from two sources, both recorded per control step:

* the **truth** (the simulator's positions and velocities): a pair's true barrier below 0,
  two vehicles closer than the collision radius, a touchdown faster than a landing;
* each **agent's own view**: the barrier it computed from its estimates below 0 (its margin
  is used up), and the :class:`~swarm_common.enums.AgentAlarm` bits it raised in flight.

An event is the onset of a condition: the step at which it becomes true for that agent or
pair, not every step it holds. The list is capped at :data:`ALARM_LIST_MAX` entries, the
earliest kept; ``safety_alarm_count`` counts them all. Pure: arrays in, plain data out.
"""

from __future__ import annotations

from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from gcs.exit_codes import EXIT_OK, EXIT_SAFETY
from gcs.report.world_metrics import WorldTruth
from swarm_common.barrier import barrier
from swarm_common.enums import AgentAlarm, Method, SafetyAlarmKind

if TYPE_CHECKING:  # compiled: imported where a run is scored, not by every CLI
    from gcs.report.pair_barriers import PairBarrierSummary

ALARM_LIST_MAX = 200  # entries kept in metrics.json (the earliest); the count is complete
# the methods that claim safety: a run of one of them that breaks it exits non-zero
SAFETY_FILTERS = frozenset({Method.DCBF, Method.RCBF})
GROUND_Z_M = 0.02  # m, an agent this low is on the ground
STRIKE_SPEED_MPS = 0.5  # m/s, descent speed above which a touchdown is a ground strike
_BIT_KIND = {
    AgentAlarm.RESIDUAL: SafetyAlarmKind.RESIDUAL,
    AgentAlarm.NEAR_ENTRY: SafetyAlarmKind.NEAR_ENTRY,
    AgentAlarm.FALLBACK: SafetyAlarmKind.FALLBACK,
    AgentAlarm.DEADLOCK: SafetyAlarmKind.DEADLOCK,
    AgentAlarm.FENCE_MISMATCH: SafetyAlarmKind.FENCE_MISMATCH,
}


class Verdict(StrEnum):
    """``metrics.json`` ``safety_verdict``."""

    SAFE = "safe"  # no event: the truth and every agent's own view held
    ALARM = "alarm"  # the truth held, but an agent's margin or an assumption broke
    UNSAFE = "unsafe"  # the truth broke: a barrier below 0, a collision or a ground strike


TRUTH_KINDS = frozenset({SafetyAlarmKind.BARRIER, SafetyAlarmKind.COLLISION,
                         SafetyAlarmKind.GROUND_STRIKE, SafetyAlarmKind.OBSTACLE,
                         SafetyAlarmKind.GEOFENCE})
# events about liveness, not safety: listed and counted, but they leave the verdict "safe"
LIVENESS_KINDS = frozenset({SafetyAlarmKind.DEADLOCK})


def onsets(cond: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(steps, columns) where the boolean (K, M) ``cond`` becomes true: true at step k and
    false at k − 1 (or k = 0), in order of step, then column."""
    if cond.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    prev = np.vstack([np.zeros((1, cond.shape[1]), bool), cond[:-1]])
    k, m = np.nonzero(cond & ~prev)
    return k, m


def pair_barrier(p: np.ndarray, v: np.ndarray, tau: float, d_safe: float,
                 vertical_scale: float = 1.0) -> np.ndarray:
    """True barrier of every unordered pair i < j at every step (m²), shape (K, N(N−1)/2):
    ``h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D²`` with Δp = p_i − p_j, Δv = v_i − v_j (paper eq. 9;
    τ in s, D in m, p in m, v in m/s); with ``vertical_scale`` κ > 1, of S Δp, S Δv,
    S = diag(1, 1, 1/κ) (the scenario's ``controller.dcbf_vertical_scale``: docs/safety.md §4c)."""
    i, j = np.triu_indices(p.shape[1], k=1)
    return barrier(p[:, i] - p[:, j], v[:, i] - v[:, j], tau, d_safe, vertical_scale)


def ground_strike_steps(p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(steps, agents) of every touchdown faster than :data:`STRIKE_SPEED_MPS`: an agent
    above :data:`GROUND_Z_M` at step k − 1 is at or below it at step k, having descended
    faster than that at k − 1 (a landing at the landing reference's 0.6 m/s ends slower).
    ``p``, ``v``: (K,N,3) true positions (m) and velocities (m/s)."""
    if len(p) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    z, vz = p[:, :, 2], v[:, :, 2]
    k, a = np.nonzero((z[1:] <= GROUND_Z_M) & (z[:-1] > GROUND_Z_M)
                      & (vz[:-1] < -STRIKE_SPEED_MPS))
    return k + 1, a


def _event(t: float, kind: SafetyAlarmKind, agent: int | None, other: int | None,
           value: float | None) -> dict[str, Any]:
    return {"t_s": round(float(t), 6), "assumption": str(kind), "agent": agent,
            "other": other, "value": None if value is None else float(value)}


def safety_events(
    t: np.ndarray, p: np.ndarray, v: np.ndarray, min_dist: np.ndarray, own_h: np.ndarray,
    alarms: np.ndarray, ids: list[int], tau_s: float, d_safe_m: float,
    collision_radius_m: float, h: PairBarrierSummary | None = None,
    world: WorldTruth | None = None,
) -> list[dict[str, Any]]:
    """Every onset, sorted by time: ``t`` (K,) s; ``p``, ``v`` (K,N,3) true positions (m)
    and velocities (m/s); ``min_dist`` (K,) the smallest pair distance over the physics
    steps of the period after t_k (m; a contact between two control steps is seen there);
    ``own_h`` (K,N) each agent's own smallest barrier (m², inf or NaN where it computed
    none); ``alarms`` (K,N) :class:`AgentAlarm` bits; ``ids`` the agents' ids in column
    order. τ (s) and D (m): the barrier's horizon and distance; ``h`` the summary of their
    :func:`pair_barrier` (:mod:`gcs.report.pair_barriers`) when the caller has it already;
    ``world`` the run's truth against its obstacles and geofence (an obstacle event names
    the obstacle's index as ``other``). A contact names the pair closest at its control step."""
    out: list[dict[str, Any]] = []
    n = p.shape[1]
    if n >= 2 and len(t):
        i, j = np.triu_indices(n, k=1)
        if h is None:
            from gcs.report.pair_barriers import pair_barrier_summary

            h = pair_barrier_summary(p, v, tau_s, d_safe_m)
        for k, m, value in zip(h.onset_steps.tolist(), h.onset_pairs.tolist(),
                               h.onset_values.tolist(), strict=True):
            out.append(_event(t[k], SafetyAlarmKind.BARRIER, ids[i[m]], ids[j[m]], value))
        with np.errstate(invalid="ignore"):
            contact = (min_dist < collision_radius_m)[:, None]
        for k, _ in zip(*onsets(contact), strict=True):
            m = int(np.argmin(np.sum((p[k, i] - p[k, j]) ** 2, axis=1)))
            out.append(_event(t[k], SafetyAlarmKind.COLLISION, ids[i[m]], ids[j[m]],
                              min_dist[k]))
    if world is not None and world.h_obs is not None:
        n_ob = world.h_obs.shape[2]
        flat = world.h_obs.reshape(len(world.h_obs), -1)  # column a·O + o
        for k, c in zip(*onsets(flat < 0.0), strict=True):
            out.append(_event(t[k], SafetyAlarmKind.OBSTACLE, ids[c // n_ob], int(c % n_ob),
                              flat[k, c]))
    if world is not None and world.h_fence is not None:
        for k, a in zip(*onsets(world.h_fence < 0.0), strict=True):
            out.append(_event(t[k], SafetyAlarmKind.GEOFENCE, ids[a], None, world.h_fence[k, a]))
    for k, a in zip(*ground_strike_steps(p, v), strict=True):
        out.append(_event(t[k], SafetyAlarmKind.GROUND_STRIKE, ids[a], None, v[k - 1, a, 2]))
    with np.errstate(invalid="ignore"):
        neg = np.nan_to_num(own_h, nan=np.inf) < 0.0
    for k, a in zip(*onsets(neg), strict=True):
        out.append(_event(t[k], SafetyAlarmKind.OWN_BARRIER, ids[a], None, own_h[k, a]))
    bits = alarms.astype(np.int64)
    for bit, kind in _BIT_KIND.items():
        for k, a in zip(*onsets((bits & int(bit)) != 0), strict=True):
            out.append(_event(t[k], kind, ids[a], None, None))
    out.sort(key=lambda e: (e["t_s"], e["assumption"], e["agent"] or 0, e["other"] or 0))
    return out


def verdict(events: list[dict[str, Any]]) -> Verdict:
    """UNSAFE when an event is one of :data:`TRUTH_KINDS`, ALARM when there are others
    (:data:`LIVENESS_KINDS` aside), SAFE when there are none."""
    if any(e["assumption"] in TRUTH_KINDS for e in events):
        return Verdict.UNSAFE
    safety = [e for e in events if e["assumption"] not in LIVENESS_KINDS]
    return Verdict.ALARM if safety else Verdict.SAFE


def verdict_metrics(
    t: np.ndarray, p: np.ndarray, v: np.ndarray, min_dist: np.ndarray, own_h: np.ndarray,
    alarms: np.ndarray, ids: list[int], follower_idx: list[int], tau_s: float,
    d_safe_m: float, collision_radius_m: float, h: PairBarrierSummary | None = None,
    world: WorldTruth | None = None,
) -> dict[str, Any]:
    """``own_h_min``, ``safety_verdict``, ``safety_alarm_count``, ``deadlock_events`` (those
    of :data:`LIVENESS_KINDS`) and ``safety_alarms`` (the first :data:`ALARM_LIST_MAX`
    events of :func:`safety_events`). ``own_h_min``: the
    smallest barrier a follower computed from its own estimates (m²; None when none did)."""
    events = safety_events(t, p, v, min_dist, own_h, alarms, ids, tau_s, d_safe_m,
                           collision_radius_m, h, world)
    own = own_h[:, follower_idx] if len(follower_idx) else own_h[:, :0]
    finite = own[np.isfinite(own)]
    return {
        "own_h_min": float(finite.min()) if finite.size else None,
        "safety_verdict": str(verdict(events)),
        "safety_alarm_count": len(events),
        "deadlock_events": sum(1 for e in events if e["assumption"] in LIVENESS_KINDS),
        "safety_alarms": events[:ALARM_LIST_MAX],
    }


def summary_line(metrics: dict[str, Any]) -> str | None:
    """One log line naming the verdict and the first events, None when the run was safe."""
    if metrics.get("safety_verdict", Verdict.SAFE) == Verdict.SAFE:
        return None
    ev = metrics.get("safety_alarms") or []
    kinds: dict[str, int] = {}
    for e in ev:
        kinds[e["assumption"]] = kinds.get(e["assumption"], 0) + 1
    first = ev[0] if ev else None
    where = ""
    if first is not None:
        pair = f"{first['agent']}" + (f"-{first['other']}" if first["other"] is not None else "")
        where = f"; first: {first['assumption']} of {pair} at t={first['t_s']:.2f} s"
    counts = ", ".join(f"{k} {n}" for k, n in kinds.items())
    return (f"safety verdict {metrics['safety_verdict'].upper()}: "
            f"{metrics.get('safety_alarm_count', len(ev))} event(s) ({counts}){where}")


def safety_exit_status(metrics: dict[str, Any], method: str) -> int:
    """``gcs mission run``'s exit status for a finished run: :data:`EXIT_SAFETY` when
    ``method`` is one of :data:`SAFETY_FILTERS` and the verdict is not "safe", else
    :data:`EXIT_OK` (a baseline without a filter, apf or none, is expected to break: its
    verdict is in the log and the metrics only)."""
    safe = metrics.get("safety_verdict", Verdict.SAFE) == Verdict.SAFE
    return EXIT_OK if safe or method not in SAFETY_FILTERS else EXIT_SAFETY
