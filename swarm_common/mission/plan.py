"""A timed formation mission: the pose (centroid m, scale, yaw rad) and every agent's desired
state xi = [p, p', p'', p'''] (m, m/s, m/s^2, m/s^3, ENU) at any time t (s).

Agent i's desired position at a pose is ``p_i = c + s Rz(psi) q_i`` with
``q_i = shape_i - mean(shape)``. A leg is a straight line in (c, s, psi) driven by one
rest-to-rest profile sigma(tau) (:mod:`swarm_common.mission.profile`), tau = (t - t0) / T:
``c = c0 + sigma dc``, ``s = s0 + sigma ds``, ``psi = psi0 + sigma dpsi``; then the formation
holds at the leg's end pose. So ``p_i(t) = P_i(sigma(tau(t)))`` with

    P_i(sigma) = c(sigma) + S(sigma) Rz(Psi(sigma)) q_i,

whose sigma-derivatives are exact (xy part as a complex number z = x + i y, e = exp(i Psi)):
``P' = dc + (ds + i S dpsi) e q``, ``P'' = (2 i ds dpsi - S dpsi^2) e q``,
``P''' = (-3 ds dpsi^2 - i S dpsi^3) e q``; z part ``P' = dc_z + ds q_z``, ``P'' = P''' = 0``.
The chain rule then gives p' = P' sigma_t, p'' = P'' sigma_t^2 + P' sigma_tt,
p''' = P''' sigma_t^3 + 3 P'' sigma_t sigma_tt + P' sigma_ttt with sigma_t = sigma' / T, ...
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from swarm_common.mission.config import MissionConfig, MissionError
from swarm_common.mission.plan_kernel import (
    agent_xi_kernel,
    hold_xi_kernel,
    legs_table,
    plan_xi_kernel,
    pose_row,
)
from swarm_common.mission.profile import POWERS, SIGMA1_PEAK, sigma_jet, sigma_jets

__all__ = ["Leg", "Limits", "MissionPlan", "Pose", "build_plan", "leg_duration"]

SAMPLES_PER_LEG = 401  # tau samples for the peak of each sigma-derivative (at least)
DURATION_MARGIN = 1.02  # T is scaled by this to cover what the sampling may miss
MIN_LEG_S = 0.5  # s, the shortest moving leg
_STILL = 1e-12  # a leg whose every change is below this does not move


@dataclass(frozen=True)
class Limits:
    """What every agent's desired motion must respect: speed (m/s), acceleration (m/s^2) and
    jerk (m/s^3) norms; every agent's desired z >= ``floor_m`` (m) at every waypoint; every
    pair of agents >= ``min_separation_m`` (m) apart at every waypoint."""

    max_speed_mps: float
    max_accel_mps2: float
    max_jerk_mps3: float
    floor_m: float
    min_separation_m: float

    def __post_init__(self) -> None:
        for name in ("max_speed_mps", "max_accel_mps2", "max_jerk_mps3"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise MissionError(f"limits.{name} = {v!r}: must be a finite number > 0")
        if not math.isfinite(self.floor_m):
            raise MissionError(f"limits.floor_m = {self.floor_m!r}: must be finite")
        if not (math.isfinite(self.min_separation_m) and self.min_separation_m >= 0.0):
            raise MissionError(
                f"limits.min_separation_m = {self.min_separation_m!r}: must be finite, >= 0"
            )


@dataclass(frozen=True, eq=False)
class Pose:
    """A formation pose: centroid (3,) m ENU, scale (1 = the scenario's shape), yaw (rad,
    about +z)."""

    centroid: np.ndarray
    scale: float
    yaw_rad: float


@dataclass(frozen=True, eq=False)
class Leg:
    """The leg arriving at waypoint ``index``: leaves ``start`` at ``t0`` (s), reaches ``end``
    ``duration_s`` (s) later (0: no motion), then holds there ``hold_s`` (s)."""

    index: int
    t0: float
    duration_s: float
    hold_s: float
    start: Pose
    end: Pose

    @property
    def arrival_s(self) -> float:
        return self.t0 + self.duration_s

    @property
    def departure_s(self) -> float:
        return self.t0 + self.duration_s + self.hold_s


def _positions(pose: Pose, q: np.ndarray) -> np.ndarray:
    """(N, 3) agent positions (m) at ``pose`` for offsets ``q`` (N, 3) (compiled:
    :func:`~swarm_common.mission.plan_kernel.hold_xi_kernel`)."""
    out = np.empty((q.shape[0], 12))
    hold_xi_kernel(float(pose.centroid[0]), float(pose.centroid[1]), float(pose.centroid[2]),
                   float(pose.scale), float(pose.yaw_rad), np.ascontiguousarray(q, dtype=float),
                   out)
    return out[:, 0:3]


def _moves(start: Pose, end: Pose) -> bool:
    return bool(
        np.max(np.abs(end.centroid - start.centroid)) > _STILL
        or abs(end.scale - start.scale) > _STILL
        or abs(end.yaw_rad - start.yaw_rad) > _STILL
    )


def leg_duration(start: Pose, end: Pose, q: np.ndarray, limits: Limits, cruise: float) -> float:
    """The shortest T (s) that keeps every agent's |p'|, |p''|, |p'''| within ``limits`` and
    the centroid's peak speed within ``cruise`` (m/s) on the leg ``start`` -> ``end``.

    At fixed geometry |p'| ~ 1/T, |p''| ~ 1/T^2, |p'''| ~ 1/T^3, so T follows in closed form
    from the peaks at T = 1, sampled densely in tau (more samples for a large turn), then
    times :data:`DURATION_MARGIN`; at least :data:`MIN_LEG_S`; 0 for a leg that does not
    move."""
    if not _moves(start, end):
        return 0.0
    turn = abs(end.yaw_rad - start.yaw_rad)
    n = max(SAMPLES_PER_LEG, int(math.ceil(32.0 * SIGMA1_PEAK * turn)) + 1)
    jets = sigma_jets(np.linspace(0.0, 1.0, n))  # tau derivatives = time derivatives at T = 1
    q = np.ascontiguousarray(q, dtype=float)
    peak = np.zeros(3)
    out = np.empty((q.shape[0], 12))
    for st in jets:  # the agents' time jets at T = 1 (the one implementation of the jet)
        agent_xi_kernel(start.centroid, end.centroid - start.centroid, start.scale,
                        end.scale - start.scale, start.yaw_rad, end.yaw_rad - start.yaw_rad,
                        q, np.ascontiguousarray(st), out)
        for k in range(3):
            if q.shape[0]:
                peak[k] = max(peak[k], float(np.max(np.linalg.norm(
                    out[:, 3 * k + 3:3 * k + 6], axis=1))))
    centroid_peak = float(np.linalg.norm(end.centroid - start.centroid)) * SIGMA1_PEAK
    t = max(
        peak[0] / limits.max_speed_mps,
        math.sqrt(peak[1] / limits.max_accel_mps2),
        math.cbrt(peak[2] / limits.max_jerk_mps3),
        centroid_peak / cruise,
    )
    return max(MIN_LEG_S, DURATION_MARGIN * t)


@dataclass(frozen=True, eq=False)
class MissionPlan:
    """The timed mission (built by :func:`build_plan`). Before the first departure and after
    the end the formation holds its pose with zero derivatives."""

    legs: tuple[Leg, ...]
    start_pose: Pose
    shape_offsets: np.ndarray  # (N, 3) m, shape - mean(shape)
    _t0: list[float] = field(init=False, repr=False)

    _tab: np.ndarray = field(init=False, repr=False)
    _start: np.ndarray = field(init=False, repr=False)
    _q: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_t0", [leg.t0 for leg in self.legs])
        # the legs as numbers for the compiled evaluation (swarm_common.mission.plan_kernel)
        object.__setattr__(self, "_tab", legs_table(self.legs))
        object.__setattr__(self, "_start", pose_row(self.start_pose))
        object.__setattr__(self, "_q", np.ascontiguousarray(self.shape_offsets, dtype=float))

    @property
    def arrival_s(self) -> tuple[float, ...]:
        """Arrival time (s) at each waypoint."""
        return tuple(leg.arrival_s for leg in self.legs)

    @property
    def departure_s(self) -> tuple[float, ...]:
        """When the formation leaves each waypoint (s): arrival + hold."""
        return tuple(leg.departure_s for leg in self.legs)

    @property
    def end_s(self) -> float:
        """The last waypoint's departure (s): the mission is over."""
        return self.legs[-1].departure_s

    @property
    def transit_window(self) -> tuple[float, float]:
        """(leaving the first waypoint, arriving at the last) (s); a 1-waypoint mission:
        (arrival, arrival)."""
        if len(self.legs) == 1:
            return (self.legs[0].arrival_s, self.legs[0].arrival_s)
        return (self.legs[0].departure_s, self.legs[-1].arrival_s)

    def _locate(self, t: float) -> tuple[Pose, Leg | None, float]:
        """(the static pose, None, 0) while holding, else (start, the moving leg, tau)."""
        k = bisect.bisect_right(self._t0, t) - 1
        if k < 0:
            return self.start_pose, None, 0.0
        leg = self.legs[k]
        if t < leg.arrival_s and leg.duration_s > 0.0:
            return leg.start, leg, (t - leg.t0) / leg.duration_s
        return leg.end, None, 0.0

    @staticmethod
    def _sigma_time(leg: Leg, tau: float) -> np.ndarray:
        """[sigma, sigma_t, sigma_tt, sigma_ttt] (1/s^k) at ``tau`` on ``leg``."""
        jet = np.array(sigma_jet(tau))
        return jet / leg.duration_s ** np.arange(4.0)

    def pose_jet(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centroid (4, 3) m, scale (4,) and yaw (4,) rad, each with its first three time
        derivatives (per s, s^2, s^3) at ``t`` (s)."""
        pose, leg, tau = self._locate(t)
        c = np.zeros((4, 3))
        s = np.zeros(4)
        y = np.zeros(4)
        if leg is None:
            c[0], s[0], y[0] = pose.centroid, pose.scale, pose.yaw_rad
            return c, s, y
        st = self._sigma_time(leg, tau)
        dc = leg.end.centroid - leg.start.centroid
        c[:] = st[:, None] * dc[None, :]
        s[:] = st * (leg.end.scale - leg.start.scale)
        y[:] = st * (leg.end.yaw_rad - leg.start.yaw_rad)
        c[0] += leg.start.centroid
        s[0] += leg.start.scale
        y[0] += leg.start.yaw_rad
        return c, s, y

    def _xi(self, t: float, q: np.ndarray) -> np.ndarray:
        """(N, 12) the jets of the agents of offsets ``q`` (N, 3, contiguous) at ``t``
        (compiled: :func:`~swarm_common.mission.plan_kernel.plan_xi_kernel`, one call for all
        of them; the same bits as :meth:`pose_jet`'s walk)."""
        out = np.empty((q.shape[0], 12))
        plan_xi_kernel(float(t), self._tab, self._start, q, POWERS, out)
        return out

    def all_xi(self, t: float) -> np.ndarray:
        """(N, 12): every agent's [p, p', p'', p'''] (m, m/s, m/s^2, m/s^3) at ``t`` (s)."""
        return self._xi(t, self._q)

    def agent_xi(self, t: float, i: int) -> np.ndarray:
        """(12,): agent ``i``'s (0-based row of the shape) [p, p', p'', p'''] at ``t`` (s)."""
        return self._xi(t, self._q[i : i + 1])[0]

    def at_rest_from(self, t: float) -> float:
        """The first time >= ``t`` (s) at which the formation is at rest: ``t`` itself
        while it holds (before a departure, at a waypoint, after the end), else the arrival
        of the leg it is flying."""
        _, leg, tau = self._locate(t)
        # the first instant of a leg is at rest too (rest-to-rest legs: zero derivatives)
        return t if leg is None or tau == 0.0 else leg.arrival_s

    def rest_pose(self, t: float) -> Pose:
        """The pose (s) at a time ``t`` when the formation is at rest (:meth:`at_rest_from`)."""
        pose, leg, tau = self._locate(t)
        if leg is None:
            return pose
        if tau == 0.0:
            return leg.start
        raise ValueError(f"t = {t:g} s: the formation is moving")

    def waypoint_at(self, t: float) -> int:
        """How many waypoints the formation has reached by ``t`` (s)."""
        return sum(1 for a in self.arrival_s if a <= t)

    def yaw_jet(self, t: float) -> np.ndarray:
        """(4,): yaw (rad) and its first three time derivatives at ``t`` (s)."""
        return self.pose_jet(t)[2]

    def centroid_at(self, t: float) -> np.ndarray:
        """(3,): the centroid (m) at ``t`` (s)."""
        return self.pose_jet(t)[0][0]


def _waypoint_pose(cfg: MissionConfig, k: int) -> Pose:
    w = cfg.waypoints[k]
    return Pose(np.array(w.centroid, dtype=float), float(w.scale), math.radians(w.yaw_deg))


def _check_waypoint(k: int, pose: Pose, q: np.ndarray, limits: Limits) -> None:
    """Refuse waypoint ``k`` if an agent is below the floor or two agents are too close.

    Along a leg z = c_z + S q_z is linear in sigma (yaw does not change z) and every pair's
    distance S |q_i - q_j| is linear in sigma too (S linear, > 0), so a leg between two poses
    that pass both checks passes them throughout: checking the waypoints suffices (leg 0
    starts at the scenario's own formation, which the scenario loader checks)."""
    where = f"mission.waypoint[{k}]"
    z = _positions(pose, q)[:, 2]
    low = int(np.argmin(z))
    if z[low] < limits.floor_m:
        raise MissionError(
            f"{where}: agent {low} at z = {z[low]:.3f} m is below the floor {limits.floor_m:.3f} m"
        )
    n = q.shape[0]
    if n < 2 or limits.min_separation_m <= 0.0:
        return
    d = np.linalg.norm(q[:, None, :] - q[None, :, :], axis=-1) * pose.scale
    d[np.diag_indices(n)] = np.inf
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    if d[i, j] < limits.min_separation_m:
        a, b = sorted((int(i), int(j)))
        raise MissionError(
            f"{where}: agents {a} and {b} are {d[i, j]:.3f} m apart at scale {pose.scale:g}, "
            f"closer than the minimum separation {limits.min_separation_m:.3f} m"
        )


def build_plan(
    cfg: MissionConfig, shape: np.ndarray, limits: Limits, start: Pose | None = None,
    start_s: float | None = None,
) -> MissionPlan:
    """Time ``cfg`` for the formation ``shape`` ((N, 3) m at scale 1, yaw 0) under ``limits``.

    Leg 0 leaves ``start`` (default: the initial pose, centroid = mean(shape), scale 1, yaw
    0) at ``start_s`` (default ``cfg.start_s``) for waypoint 0; leg k leaves waypoint k-1 at
    its departure. Each leg takes :func:`leg_duration` with the waypoint's cruise speed (or
    the mission's). Raises :class:`MissionError` naming the waypoint where an agent is below
    ``limits.floor_m`` or two agents are closer than ``limits.min_separation_m`` (see
    :func:`_check_waypoint`)."""
    pts = np.asarray(shape, dtype=float)
    if pts.ndim != 2 or pts.shape[0] < 1 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
        raise MissionError(f"shape of shape {pts.shape}: must be a finite (N, 3) array, N >= 1")
    q = pts - pts.mean(axis=0)
    if start is None:
        start = Pose(pts.mean(axis=0), 1.0, 0.0)
    poses = [_waypoint_pose(cfg, k) for k in range(len(cfg.waypoints))]
    for k, pose in enumerate(poses):
        _check_waypoint(k, pose, q, limits)
    legs: list[Leg] = []
    t0, prev = float(cfg.start_s if start_s is None else start_s), start
    for k, (w, pose) in enumerate(zip(cfg.waypoints, poses, strict=True)):
        cruise = w.speed_mps if w.speed_mps is not None else cfg.speed_mps
        leg = Leg(k, t0, leg_duration(prev, pose, q, limits, cruise), w.hold_s, prev, pose)
        legs.append(leg)
        t0, prev = leg.departure_s, pose
    return MissionPlan(legs=tuple(legs), start_pose=start, shape_offsets=q)
