"""Leader agent: PD + feed-forward on its own trajectory with a small velocity ESO for its
disturbance (Departure 4). It publishes its state predicted for t_{k+1} and ξ_L(t_{k+1})."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from offboard.agent.base import CLIP_TOL, AgentBase
from offboard.agent.governor import governor_for, log_governor
from offboard.agent.leader_guard import leader_guard
from offboard.agent.takeoff import climb_xi, leader_origin
from offboard.estimation.bearing import Formation
from offboard.estimation.peer_table import EstimateBatch
from offboard.estimation.reference import LeaderTrajectory, xi_at_rest, xi_p
from offboard.records import AgentOutput, AgentStatus, NeighbourEstimate
from swarm_common.enums import Method
from swarm_common.fastnp import f64
from swarm_common.jit import CallSite, kernel
from swarm_common.mission.config import MissionConfig, MissionError
from swarm_common.mission.timeline import MissionTimeline
from swarm_common.scenario.flight_check import checked_timeline
from swarm_common.scenario.mission_check import turn_problem
from swarm_common.scenario.model import Scenario


class LeaderAgent(AgentBase):
    """Leader: tracks p_L(t) = p_L(0) + A(1 − cos ωt) with its own state (Departure 4), or
    its share of the scenario's formation mission (docs/missions.md)."""

    is_leader = True

    def __init__(
        self, sc: Scenario, agent_id: int, method: Method | str | None = None,
        seed: int | None = None, form: Formation | None = None,
    ) -> None:
        super().__init__(sc, agent_id, method)
        ctl = sc.controller
        self.kp, self.kd = ctl.leader_kp, ctl.leader_kd
        lt = sc.leader_trajectory
        # the governed (possibly slowed) trajectory, the same on every agent (docs/saturation.md)
        self.governor = governor_for(sc)
        log_governor(self.governor, agent_id)
        self.traj = LeaderTrajectory(
            leader_origin(sc, self.index), np.array(lt.amplitude_m), self.governor.frequency_hz
        )
        # a [mission] replaces the sinusoid: its timeline (the plan, then what ground-station
        # commands change) gives this leader's ξ at mission time
        self.timeline = checked_timeline(sc) if sc.mission is not None else None
        self._last_xi: tuple[float, int, np.ndarray] | None = None
        # velocity ESO: v̂' = u + d̂ + l1 (v − v̂),  d̂' = l2 (v − v̂)   (double pole at −5)
        self.l1, self.l2 = 10.0, 25.0
        self.v_hat = sc.agents[self.index].velocity.astype(float).copy()
        self.d_hat = np.zeros(3)
        # the kernels' call sites: arguments through f64 or the leader's own buffers
        self._control = CallSite(leader_control_kernel)
        self._predict = CallSite(leader_prediction_kernel)
        self._eso = CallSite(velocity_eso_kernel)
        self.start_time = 0.0
        self.gains = None
        # dcbf: the pairs with the scenario's non-cooperative agents are the leader's to keep
        # (offboard.agent.leader_guard); None where there are none
        self.guard = (leader_guard(sc, self.index, agent_id,
                                   sc.seed if seed is None else int(seed), self.u_lo, self.u_hi)
                      if self.cooperative else None)

    def reference(self, t: float) -> np.ndarray:
        """ξ_L(t) = [p, ṗ, p̈, p⃛] of the leader trajectory; held at p_L(0) before
        ``start_time`` (0 in lockstep; in real time the daemon sets the first whole
        trajectory period after arming, the same for both leaders, so the motion starts
        smoothly and the leaders stay in step). Ground start (offboard.agent.takeoff): the climb
        from the pad, held at the staging point p_L(0) until the plan's ``t_traj`` (at rest
        on the pad while held for the take-off command). The trajectory's phase counts from
        its start, so it starts at rest also when the governed period (offboard.agent.governor)
        does not divide the start time."""
        tk = self.takeoff_clock(t)
        t_start = self.start_time
        if self.takeoff is not None:
            if tk < max(self.start_time, self.takeoff.t_traj):
                return climb_xi(self.takeoff, self.index, tk)
            t_start = max(self.start_time, self.takeoff.t_traj)
        if t < self.start_time:
            return xi_at_rest(xi_p(self.trajectory_state(0.0)))
        return self.trajectory_state(t - t_start)

    def trajectory_state(self, tau: float) -> np.ndarray:
        """ξ (12,) ``tau`` (s) after the trajectory's start: the mission plan's for this
        leader, else the sinusoid's."""
        tl = self.timeline
        if tl is not None:
            # a step asks for t_k and t_k+1, the next one for t_k+1 again: keep the last
            # (valid while no new plan was installed)
            last = self._last_xi
            if last is not None and last[0] == tau and last[1] == tl.revision:
                return last[2].copy()
            xi = tl.agent_xi(tau, self.index)
            self._last_xi = (tau, tl.revision, xi)
            return xi.copy()
        return self.traj.state(tau)

    def fly_mission(self, cfg: MissionConfig, at_s: float) -> float:
        """Fly ``cfg``'s formation waypoints from the first rest at or after mission time
        ``at_s`` (:meth:`MissionTimeline.fly`); returns when (mission time, s). Raises
        :class:`MissionError` (nothing changed) when it cannot be flown from there, or when
        the scenario has no mission (the sinusoid cannot be left mid-way)."""
        problem = turn_problem(self.sc, cfg)
        if problem is not None:
            raise MissionError(problem)
        return self._mission_time(self._timeline().fly(cfg, at_s - self._t0()))

    def hold_formation(self, at_s: float) -> float:
        """Stop at the first rest at or after mission time ``at_s``; returns when (s)."""
        return self._mission_time(self._timeline().hold(at_s - self._t0()))

    def fly_live(self, velocity: np.ndarray, at_s: float) -> float:
        """Fly the formation's centroid at ``velocity`` (m/s, ENU) from mission time
        ``at_s`` (:meth:`MissionTimeline.live`: then it brakes to rest by itself unless a
        newer velocity follows); returns when (s). Raises :class:`MissionError` (nothing
        changed) when the leaders could not fly it, or the scenario has no mission."""
        return self._mission_time(self._timeline().live(velocity, at_s - self._t0()))

    def _timeline(self) -> MissionTimeline:
        if self.timeline is None:
            raise MissionError("the scenario has no [mission]: its leaders fly the sinusoid")
        return self.timeline

    def _t0(self) -> float:
        """Mission time (s) of the trajectory's start (0 in lockstep and in process)."""
        return self.start_time if math.isfinite(self.start_time) else 0.0

    def _mission_time(self, tau: float) -> float:
        return tau + self._t0()

    def current_reference(self, t: float) -> np.ndarray:
        """The landing reference once landing, else :meth:`reference`."""
        if self.landing is not None:
            return self.landing.xi(t)
        return self.reference(t)

    def initial_estimate(self) -> NeighbourEstimate:
        spec = self.sc.agents[self.index]
        return NeighbourEstimate(
            self.id, 0.0, spec.position.astype(float).copy(), spec.velocity.astype(float).copy(),
            np.zeros(3), self.reference(0.0) if self.takeoff else self.trajectory_state(0.0), True,
        )

    def step(
        self,
        k: int,
        t: float,
        truth_p: np.ndarray,
        truth_v: np.ndarray,
        neighbours: Mapping[int, NeighbourEstimate] | EstimateBatch,
        comm_ok: bool = True,
    ) -> AgentOutput:
        p = f64(truth_p[self.index])
        v = f64(truth_v[self.index])
        # PD + feed-forward with lag compensation, clipped to the box (one compiled call)
        u = np.empty(3)  # new arrays from Python here: cheaper than ones the kernels box
        self._control.call(
            f64(self.current_reference(t)), p, v, self.d_hat, self.veh.tau_rollpitch_s,
            self.kp, self.kd, self.u_lo, self.u_hi, u,
        )
        status = AgentStatus(method=self.method, comm_ok=comm_ok, u_nom=u)
        guarded = self.guard is not None and self.method == Method.DCBF
        if self.guard is not None and guarded:  # the nominal goes through its filter
            u = self.guard.apply(t, truth_p, truth_v, u, self.d_hat, status)
        if self.landing is not None:
            u = self.landed_idle(t, float(p[2]), u)
        u = self.on_pad_floor(t, float(p[2]), u)
        if not guarded:  # no filter: its command is its nominal control
            status.u_nom = u
        sp, u_sub, clipped, u_mean = self.inner.command(u, self.yaw, self.substeps, CLIP_TOL)
        status.input_clipped = clipped
        if self.guard is not None:
            self.guard.realised(u, u_sub[-1], u_mean)
        self._update_eso(v, u_sub)
        pv = np.empty((2, 3))
        self._predict.call(p, v, u_mean, self.d_hat, self.dt, pv)
        est = NeighbourEstimate(
            self.id, t + self.dt, pv[0], pv[1], self.d_hat.copy(),
            self.current_reference(t + self.dt), True,
        )
        return self._output(sp, u, est, status, self.d_hat.copy())

    def _update_eso(self, v: np.ndarray, u_sub: np.ndarray) -> None:
        """Velocity ESO over the period (sub-stepped Euler, measurement ``v`` held;
        compiled: :func:`velocity_eso_kernel`)."""
        out = np.empty((2, 3))
        self._eso.call(
            f64(v), self.v_hat, self.d_hat, f64(u_sub), self.dt / self.substeps, self.l1,
            self.l2, out,
        )
        self.v_hat, self.d_hat = out[0], out[1]


@kernel
def velocity_eso_kernel(
    v: np.ndarray, v_hat: np.ndarray, d_hat: np.ndarray, u_sub: np.ndarray, dl: float,
    l1: float, l2: float, out: np.ndarray,
) -> None:
    """(v̂, d̂) into the rows of ``out`` (2,3), the caller's new array (none to box; not
    ``v_hat`` or ``d_hat``), after ``len(u_sub)`` Euler sub-steps of dl (s) of the leader's
    velocity ESO
    ``v̂' = u + d̂ + l1 (v − v̂)``, ``d̂' = l2 (v − v̂)`` with the measured velocity v (m/s)
    held and u (m/s²) the inner-loop model's realised control per sub-step. Per axis the
    operations and their order of the numpy formulation (``v̂ + dl·((u + d̂) + l1·e)``,
    ``d̂ + (dl·l2)·e``), so the same bits."""
    vh = out[0]
    dh = out[1]
    for a in range(3):
        vh[a] = v_hat[a]
        dh[a] = d_hat[a]
    k = dl * l2
    for s in range(u_sub.shape[0]):
        for a in range(3):
            err = v[a] - vh[a]
            vh[a] = vh[a] + dl * (u_sub[s, a] + dh[a] + l1 * err)
            dh[a] = dh[a] + k * err


@kernel
def leader_control_kernel(
    ref: np.ndarray, p: np.ndarray, v: np.ndarray, d_hat: np.ndarray, tau: float, kp: float,
    kd: float, lo: np.ndarray, hi: np.ndarray, u: np.ndarray,
) -> None:
    """The leader's command (m/s²) into ``u`` (3,), the caller's new array (none to box):
    ``a_ff − d̂ + k_p (p* − p) + k_d (v* − v)`` with the
    lag-compensating feed-forward ``a_ff = a* + τ j*`` of ξ = ``ref`` (12,), own position
    p (m) and velocity v (m/s), the ESO's disturbance d̂ (m/s²), clipped to [lo, hi].
    Per axis the numpy formulation's operations in its order (left to right), and
    ``np.clip``'s (a NaN stays NaN), so the same bits."""
    for a in range(3):
        a_ff = ref[6 + a] + tau * ref[9 + a]
        x = a_ff - d_hat[a] + kp * (ref[a] - p[a]) + kd * (ref[3 + a] - v[a])
        if x < lo[a]:
            x = lo[a]
        if x > hi[a]:
            x = hi[a]
        u[a] = x


@kernel
def leader_prediction_kernel(
    p: np.ndarray, v: np.ndarray, u_mean: np.ndarray, d_hat: np.ndarray, dt: float,
    out: np.ndarray,
) -> None:
    """(p, v) one period ``dt`` (s) ahead at the constant acceleration a = ū + d̂ (the
    period's mean realised control and the disturbance, m/s²), into the rows of ``out``
    (2,3), the caller's new array (none to box): ``p + v dt + ½ a dt²``, ``v + a dt``;
    the numpy formulation's operations in its order, so the same bits."""
    dt2 = dt**2
    for i in range(3):
        a = u_mean[i] + d_hat[i]
        out[0, i] = p[i] + v[i] * dt + 0.5 * a * dt2
        out[1, i] = v[i] + a * dt
