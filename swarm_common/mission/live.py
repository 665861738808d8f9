"""A formation flown live: the centroid follows a velocity streamed by a ground station.

A :class:`LivePlan` starts at ``start_s`` (s) from the centroid's state (c0 m, v0 m/s, a0
m/s^2, ENU) with the scale and yaw of that moment, both held constant; it reads like a
:class:`~swarm_common.mission.plan.MissionPlan` (same methods and attributes, no legs), so
every agent's desired position is ``p_i = c(t) + s Rz(psi) q_i`` and its derivatives are the
centroid's. The centroid flies four segments (times from ``start_s``):

1. blend, [0, T1]: the velocity is the cubic v(tau) = v0 + a0 tau + b tau^2 + k tau^3 with
   v(0) = v0, v'(0) = a0, v(T1) = v*, v'(T1) = 0, i.e. b = (3 D - 2 a0 T1) / T1^2,
   k = (a0 T1 - 2 D) / T1^3, D = v* - v0; the position is its exact integral from c0;
2. cruise at v* until :data:`LIVE_TIMEOUT_S` after the start (empty if T1 is longer): a
   velocity holds that long unless a new command replaces it (PX4's offboard-loss timeout);
3. brake, from B = max(T1, LIVE_TIMEOUT_S): the same cubic from (v*, 0) to (0, 0) over T2;
4. rest at the final centroid forever (:attr:`LivePlan.rest_s` = B + T2, ``arrival_s``).

A zero v* is a stop: the plan rests from T1 on (no cruise, T2 = 0).

T1 and T2 are the shortest durations (>= :data:`MIN_BLEND_S`) that keep the centroid's
|v| <= ``max_speed_mps``, |a| <= ``max_accel_mps2`` and |jerk| <= ``max_jerk_mps3``. With
a0 = 0 (every brake; a blend from rest) the velocity is a convex combination of v0 and v*
(so |v| <= max(|v0|, |v*|)), |a| peaks at 1.5 |D| / T mid-blend and |jerk| at 6 |D| / T^2
at both ends: T = max(MIN_BLEND_S, 1.5 |D| / a_max, sqrt(6 |D| / j_max)), exact. With
a0 != 0 the jerk is linear in tau, so its peak is at an end, exact; |v| and |a| are sampled
at :data:`BLEND_SAMPLES` points and T is the first of a geometric grid (ratio
:data:`GRID_RATIO`, a margin of its own) that passes. A start accelerating outwards near the
speed limit may admit no such T (a jerk-limited turn-around overshoots by a0^2 / (2 j_max));
then T is the grid's least worst ratio to the limits. The jerk jumps at segment starts
(position, velocity and acceleration are continuous).

:meth:`MissionTimeline.live <swarm_common.mission.timeline.MissionTimeline.live>` starts a
live plan at the command's ``at_s`` when the plan in force there is live, at rest, or on a
leg that only translates (from that plan's centroid jet there); on a leg that scales or
turns, at that leg's arrival (from rest). A new live command replaces the previous one at
its ``at_s``; a go-to or hold after a live stream waits for the live plan's final rest.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from swarm_common.mission.config import MissionError
from swarm_common.mission.plan import Leg, Limits, Pose

__all__ = ["LIVE_TIMEOUT_S", "LivePlan", "blend_duration", "live_plan"]

LIVE_TIMEOUT_S = 1.0  # s: a velocity holds this long after its start, then the plan brakes
MIN_BLEND_S = 0.2  # s, the shortest blend or brake
BLEND_SAMPLES = 201  # tau samples of |v| and |a| per candidate duration (a0 != 0)
GRID_RATIO = 1.01  # ratio of successive candidate durations (a0 != 0)
FLOOR_STEP_S = 0.05  # s, the sampling step of the floor check
_FACT = np.array([[1.0, 1.0, 1.0, 1.0, 1.0], [1.0, 2.0, 3.0, 4.0, 0.0],
                  [2.0, 6.0, 12.0, 0.0, 0.0], [6.0, 24.0, 0.0, 0.0, 0.0]])


def _blend_coeffs(c0: np.ndarray, v0: np.ndarray, a0: np.ndarray, v1: np.ndarray,
                  t: float) -> np.ndarray:
    """(5, 3): the position quartic's coefficients (of tau^0..4) of a blend (module
    docstring) from (c0 m, v0 m/s, a0 m/s^2) to velocity ``v1`` (m/s) over ``t`` (s)."""
    d = v1 - v0
    b = (3.0 * d - 2.0 * a0 * t) / (t * t)
    k = (a0 * t - 2.0 * d) / (t * t * t)
    return np.stack([c0, v0, 0.5 * a0, b / 3.0, 0.25 * k])


def _derivs(coeffs: np.ndarray) -> np.ndarray:
    """(..., 4, 5, 3): for quartics ``coeffs`` (..., 5, 3) (of tau^0..4), the coefficients of
    their 0th to 3rd derivatives: d^m/dtau^m sum_j C_j tau^j = sum_j C_(j+m) (j+m)!/j! tau^j."""
    out = np.zeros((*coeffs.shape[:-2], 4, 5, 3))
    for m in range(4):
        out[..., m, : 5 - m, :] = _FACT[m, : 5 - m, None] * coeffs[..., m:, :]
    return out


def _jets(derivs: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(K, 4, 3): position and its first three derivatives at local times ``tau`` (K,) (s)
    of the quartics of derivative coefficients ``derivs`` (K, 4, 5, 3) (:func:`_derivs`)."""
    pw = tau[:, None] ** np.arange(5.0)[None, :]
    return np.einsum("kj,kmjd->kmd", pw, derivs)


def blend_duration(v0: np.ndarray, a0: np.ndarray, v1: np.ndarray, limits: Limits) -> float:
    """The shortest blend time T (s) from (v0 m/s, a0 m/s^2) to (``v1``, 0) that keeps the
    centroid's speed, acceleration and jerk within ``limits`` (module docstring)."""
    d = np.asarray(v1, float) - np.asarray(v0, float)
    v0, a0 = np.asarray(v0, float), np.asarray(a0, float)
    dn, an = float(np.linalg.norm(d)), float(np.linalg.norm(a0))
    closed = max(MIN_BLEND_S, 1.5 * dn / limits.max_accel_mps2,
                 math.sqrt(6.0 * dn / limits.max_jerk_mps3))
    if an == 0.0:
        return closed
    cap = 4.0 * max(closed, 4.0 * an / limits.max_jerk_mps3)
    n = int(math.ceil(math.log(cap / MIN_BLEND_S) / math.log(GRID_RATIO))) + 1
    ts = MIN_BLEND_S * GRID_RATIO ** np.arange(n)  # (n,)
    u = np.linspace(0.0, 1.0, BLEND_SAMPLES)[None, :, None]
    s0, h0 = u * u * (3.0 - 2.0 * u), u * (1.0 - u) ** 2  # Hermite bases (v = v0 + ...)
    s1, h1 = 6.0 * u * (1.0 - u), 1.0 - 4.0 * u + 3.0 * u * u  # their u-slopes

    def worst(t: np.ndarray) -> np.ndarray:
        """(K,) the largest ratio of |v|, |a|, |jerk| to its limit for blend times t (K,)."""
        tt = t[:, None, None]
        v = v0 + d * s0 + tt * a0 * h0  # (K, m, 3)
        a = d * s1 / tt + a0 * h1
        j = np.stack([6.0 * d - 4.0 * a0 * t[:, None], 2.0 * a0 * t[:, None] - 6.0 * d])
        return np.max(np.stack([  # the jerk is linear in tau: its peak is at an end
            np.max(np.linalg.norm(v, axis=2), axis=1) / limits.max_speed_mps,
            np.max(np.linalg.norm(a, axis=2), axis=1) / limits.max_accel_mps2,
            np.max(np.linalg.norm(j, axis=2), axis=0) / t**2 / limits.max_jerk_mps3,
        ]), axis=0)

    jerk = np.maximum(np.linalg.norm(6.0 * d - 4.0 * a0 * ts[:, None], axis=1),
                      np.linalg.norm(2.0 * a0 * ts[:, None] - 6.0 * d, axis=1)) / ts**2
    first = int(np.argmax(jerk <= limits.max_jerk_mps3))  # no shorter T keeps the jerk
    for lo in range(first, n, 32):  # a chunk at a time: the first T that passes wins
        ok = np.flatnonzero(worst(ts[lo : lo + 32]) <= 1.0)
        if ok.size:
            return float(ts[lo + ok[0]])
    return float(ts[int(np.argmin(worst(ts)))])  # none passes: the least worst ratio


@dataclass(frozen=True, eq=False)
class LivePlan:
    """A live plan (module docstring; built by :func:`live_plan`): the centroid's quartic
    ``coeffs`` (4, 5, 3) on the segments starting at ``segment_s`` (s): blend, cruise, brake,
    rest. Before ``start_s`` (not in force there) it gives the start state."""

    start_s: float
    velocity: np.ndarray  # (3,) m/s, the commanded v*
    start_pose: Pose  # the centroid (m), scale and yaw (rad) at start_s
    shape_offsets: np.ndarray  # (N, 3) m, shape - mean(shape)
    segment_s: tuple[float, float, float, float]
    coeffs: np.ndarray
    legs: tuple[Leg, ...] = field(default=(), init=False)
    _derivs: np.ndarray = field(init=False, repr=False)  # (4, 4, 5, 3) per segment

    def __post_init__(self) -> None:
        object.__setattr__(self, "_derivs", _derivs(self.coeffs))

    @property
    def rest_s(self) -> float:
        """When the formation comes to rest after the timeout brake (s)."""
        return self.segment_s[3]

    @property
    def arrival_s(self) -> tuple[float, ...]:
        return (self.rest_s,)

    @property
    def departure_s(self) -> tuple[float, ...]:
        return (self.rest_s,)

    @property
    def end_s(self) -> float:
        return self.rest_s

    @property
    def transit_window(self) -> tuple[float, float]:
        """(start, rest) (s)."""
        return (self.start_s, self.rest_s)

    def _centroid_jets(self, t: np.ndarray) -> np.ndarray:
        """(K, 4, 3) the centroid (m) and its first three time derivatives at times ``t``."""
        t = np.maximum(np.asarray(t, float), self.start_s)
        k = np.searchsorted(np.asarray(self.segment_s), t, side="right") - 1
        return _jets(self._derivs[k], t - np.asarray(self.segment_s)[k])

    def _jet(self, t: float) -> np.ndarray:
        """(4, 3) the centroid's jet at one time ``t`` (s) (:meth:`_centroid_jets`)."""
        t = max(float(t), self.start_s)
        k = bisect.bisect_right(self.segment_s, t) - 1
        pw = (t - self.segment_s[k]) ** np.arange(5.0)
        return np.einsum("j,mjd->md", pw, self._derivs[k])

    def pose_jet(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centroid (4, 3) m, scale (4,) and yaw (4,) rad, each with its first three time
        derivatives at ``t`` (s) (scale and yaw are constant)."""
        c = self._jet(t)
        s, y = np.zeros(4), np.zeros(4)
        s[0], y[0] = self.start_pose.scale, self.start_pose.yaw_rad
        return c, s, y

    def _xi(self, t: float, q: np.ndarray) -> np.ndarray:
        c = self._jet(t)
        cs, sn = math.cos(self.start_pose.yaw_rad), math.sin(self.start_pose.yaw_rad)
        rot = self.start_pose.scale * np.array([[cs, -sn, 0.0], [sn, cs, 0.0], [0.0, 0.0, 1.0]])
        out = np.empty((q.shape[0], 12))
        out[:, 0:3] = c[0] + q @ rot.T
        out[:, 3:12] = c[1:].reshape(9)
        return out

    def all_xi(self, t: float) -> np.ndarray:
        """(N, 12): every agent's [p, p', p'', p'''] (m, m/s, m/s^2, m/s^3) at ``t`` (s)."""
        return self._xi(t, self.shape_offsets)

    def agent_xi(self, t: float, i: int) -> np.ndarray:
        """(12,): agent ``i``'s [p, p', p'', p'''] at ``t`` (s)."""
        return self._xi(t, self.shape_offsets[i : i + 1])[0]

    def _still_at_start(self) -> bool:
        return not (np.any(self.coeffs[0, 1]) or np.any(self.coeffs[0, 2]))

    def at_rest_from(self, t: float) -> float:
        """The first time >= ``t`` (s) at rest: ``t`` from :attr:`rest_s` on (and at a start
        from rest), else :attr:`rest_s` (a later command waits for the brake)."""
        if t >= self.rest_s or (t == self.start_s and self._still_at_start()):
            return t
        return self.rest_s

    def rest_pose(self, t: float) -> Pose:
        """The pose at a time ``t`` (s) when the formation is at rest (:meth:`at_rest_from`)."""
        if self.at_rest_from(t) != t:
            raise ValueError(f"t = {t:g} s: the formation is moving")
        return Pose(self.centroid_at(t), self.start_pose.scale, self.start_pose.yaw_rad)

    def waypoint_at(self, t: float) -> int:
        """0: a live plan has no waypoints."""
        return 0

    def yaw_jet(self, t: float) -> np.ndarray:
        """(4,): yaw (rad), constant, and its (zero) derivatives."""
        return self.pose_jet(t)[2]

    def centroid_at(self, t: float) -> np.ndarray:
        """(3,): the centroid (m) at ``t`` (s)."""
        return self.pose_jet(t)[0][0]


def _vec(name: str, value: object) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = np.full(0, np.nan)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise MissionError(f"live {name} = {value!r}: must be 3 finite numbers")
    return v


def live_plan(
    start_s: float, c0: np.ndarray, v0: np.ndarray, a0: np.ndarray, pose_scale: float,
    pose_yaw: float, velocity: object, shape_offsets: np.ndarray, limits: Limits,
) -> LivePlan:
    """The :class:`LivePlan` from the centroid state (``c0`` m, ``v0`` m/s, ``a0`` m/s^2) at
    ``start_s`` (s), scale ``pose_scale`` and yaw ``pose_yaw`` (rad) to the centroid velocity
    ``velocity`` (3,) m/s ENU, for offsets ``shape_offsets`` (N, 3) m under ``limits``.
    Raises :class:`MissionError` (one line) when ``velocity`` is not 3 finite numbers or
    faster than ``limits.max_speed_mps``, or when an agent's desired z would go below
    ``limits.floor_m`` (sampled every :data:`FLOOR_STEP_S` s until rest, and at rest)."""
    vel = _vec("velocity", velocity)
    speed = float(np.linalg.norm(vel))
    if speed > limits.max_speed_mps:
        raise MissionError(f"live velocity = {vel.tolist()}: {speed:g} m/s is faster than "
                           f"limits.max_speed_mps = {limits.max_speed_mps:g}")
    c0, v0, a0 = _vec("c0", c0), _vec("v0", v0), _vec("a0", a0)
    if not (math.isfinite(start_s) and math.isfinite(pose_scale) and pose_scale > 0.0
            and math.isfinite(pose_yaw)):
        raise MissionError(f"live start ({start_s!r} s, scale {pose_scale!r}, yaw "
                           f"{pose_yaw!r} rad): must be finite, scale > 0")
    q = np.asarray(shape_offsets, dtype=float)
    t1 = blend_duration(v0, a0, vel, limits)
    blend = _blend_coeffs(c0, v0, a0, vel, t1)
    end1 = _jets(_derivs(blend[None]), np.array([t1]))[0, 0]
    if speed == 0.0:  # a stop: at rest from the blend's end
        brake_at, t2 = t1, 0.0
        cruise = brake = np.stack([end1, *np.zeros((4, 3))])
    else:
        brake_at = max(t1, LIVE_TIMEOUT_S)
        t2 = blend_duration(vel, np.zeros(3), np.zeros(3), limits)
        cruise = np.stack([end1, vel, *np.zeros((3, 3))])
        brake = _blend_coeffs(end1 + vel * (brake_at - t1), vel, np.zeros(3), np.zeros(3), t2)
    final = _jets(_derivs(brake[None]), np.array([t2]))[0, 0]
    rest = np.stack([final, *np.zeros((4, 3))])
    t0 = float(start_s)
    plan = LivePlan(
        start_s=t0, velocity=vel, start_pose=Pose(c0, float(pose_scale), float(pose_yaw)),
        shape_offsets=q, segment_s=(t0, t0 + t1, t0 + brake_at, t0 + brake_at + t2),
        coeffs=np.stack([blend, cruise, brake, rest]),
    )
    times = np.append(np.arange(t0, plan.rest_s, FLOOR_STEP_S), plan.rest_s)
    z = plan._centroid_jets(times)[:, 0, 2] + pose_scale * (float(np.min(q[:, 2])) if q.size
                                                             else 0.0)
    low = int(np.argmin(z))
    if z[low] < limits.floor_m:
        raise MissionError(
            f"live velocity = {vel.tolist()}: the lowest agent would reach z = {z[low]:.3f} m "
            f"at t = {times[low]:.2f} s, below the floor {limits.floor_m:.3f} m"
        )
    return plan
