"""Per-agent control step: the ONE object the in-process runner and the daemon both call.

Interface (all vectors ENU, z up; agents addressed by id, arrays in scenario order)::

    agent = make_agent(sc, agent_id, method="rcbf", seed=None)   # FollowerAgent | LeaderAgent
    est0 = agent.initial_estimate()          # NeighbourEstimate valid for t_0 (publish first)
    out = agent.step(k, t, truth_p, truth_v, neighbours, comm_ok)   # -> AgentOutput
    agent.set_method("apf")                  # rcbf | apf | none, switchable at run time
    agent.gains                              # DESO GainReport (followers), print .lines()

* ``truth_p``/``truth_v``: (N,3) float32-rounded ground truth of all agents at t_k. A
  follower uses them ONLY through its :class:`~offboard.sensing.Sensor` (relative
  bearing/range measurements); it never reads its own row. A leader reads its own row.
* ``neighbours``: {id: NeighbourEstimate} published by the others at step k−1 (post-update,
  i.e. valid for t_k). Missing entries or ``comm_ok=False`` (outage, errata 16): the agent
  predicts the last received data to t_k (constant velocity for followers' z, the
  exosystem for ξ and for leaders' broadcast state).
* ``AgentOutput``: the attitude/thrust setpoint (as decoded from the float32 wire form),
  the MAVLink payload (``q_ned`` wxyz float32, ``thrust_norm`` float32), ``u`` (ENU
  virtual control), ``estimate`` (to publish, valid for t_{k+1}) and ``status``.

Follower step k: sense (t_k) → predict neighbours to t_k → controller on (z(t_k), ξ̂(t_k))
→ setpoint → inner-loop model → DESO and desired-state observer advanced to t_{k+1} →
publish. Leader step k: PD + feed-forward on its own trajectory with a small velocity
ESO for its disturbance; publishes its state predicted for t_{k+1} and ξ_L(t_{k+1}).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from offboard.apf import apf_control, none_control
from offboard.attitude import InnerLoopModel, Setpoint, accel_from_attitude, setpoint_from_accel
from offboard.bearing import Formation, formation_from_scenario
from offboard.clf_rcbf import (
    QPResult,
    SafetyQP,
    barrier,
    clf_terms,
    rcbf_rows,
    tangential_term,
)
from offboard.deso import DESO, GainReport, gain_report
from offboard.reference import DesiredStateObserver, LeaderTrajectory, exo_propagator
from offboard.sensing import Sensor

METHODS = ("rcbf", "apf", "none")
W_MAX = 2.0  # m/s², bound on the lumped-disturbance estimate used by the controller
W_SAFE = 0.5  # m/s², bound on the same estimate inside the RCBF rows
SENSE_HOLD_S = 0.2  # s, a dropped pair's last measurement is extrapolated this long


@dataclass
class NeighbourEstimate:
    """What an agent publishes: its estimate valid at time ``t``."""

    id: int
    t: float
    z1: np.ndarray  # position (leaders: true, predicted)
    z2: np.ndarray  # velocity
    z3: np.ndarray  # lumped disturbance estimate (m/s²)
    xi: np.ndarray  # (12,) desired-state estimate [p*, v*, a*, j*] (leaders: ξ_L)
    is_leader: bool = False


@dataclass
class AgentStatus:
    """Per-step status record (for the ground station / metrics)."""

    method: str
    qp_status: str = "inactive"
    solve_us: float = 0.0
    h_min: float = float("inf")
    V: float = 0.0
    slack: float = 0.0
    violation: float = 0.0
    fallbacks: int = 0  # cumulative
    n_sensed: int = 0
    n_used: int = 0
    comm_ok: bool = True


@dataclass
class AgentOutput:
    roll: float
    pitch: float
    yaw: float
    thrust_n: float
    q_ned: np.ndarray  # float32 (4,) w, x, y, z
    thrust_norm: np.float32
    u: np.ndarray  # ENU virtual control
    estimate: NeighbourEstimate
    status: AgentStatus
    lumped: np.ndarray = field(default_factory=lambda: np.zeros(3))  # z3 + Φζ̂ (m/s²)


def control_box(sc) -> tuple[np.ndarray, np.ndarray]:
    """Box on u that the tilt/thrust limits can realise (paper §4.4 ‖u‖∞ ≤ u_max, tightened).

    z in [−u_max, u_max]; horizontal per axis ``(g − 2) tan(tilt)/√2`` (tilt cone at
    u_z ≥ −2 m/s²), at most u_max.
    """
    veh, ctl = sc.vehicle, sc.controller
    umax = ctl.u_max_mps2
    g = veh.gravity_mps2
    uz_lo = min(umax, 0.9 * g)
    uz_hi = min(umax, veh.thrust_max_n / veh.mass_kg - g)
    uh = min(umax, (g - 2.0) * math.tan(math.radians(veh.tilt_max_deg)) / math.sqrt(2.0))
    return np.array([-uh, -uh, -uz_lo]), np.array([uh, uh, uz_hi])


_EXO_CACHE: dict[tuple[float, float, int], np.ndarray] = {}
_ERR_CACHE: dict[tuple[float, float, float, int], np.ndarray] = {}


class _Predictor:
    """Last received estimate per agent, predicted to a requested time (errata 16).

    The desired state ξ is propagated by the exosystem; the agent's offset from it
    (e1 = z1 − p*, e2 = z2 − v*) by the closed-loop error dynamics every agent shares,
    ``ë1 = −k_v ė1 − k_p' e1`` (the nominal controller's; the leaders' PD for leaders).
    """

    def __init__(self, omega: float, dt: float, fol_gains: tuple[float, float],
                 lead_gains: tuple[float, float], max_age: float = math.inf) -> None:
        self.omega = omega
        self.dt = dt
        self.max_age = max_age  # older data is dropped, not predicted (communication.max_age_s)
        self.gains = {False: fol_gains, True: lead_gains}
        self.last: dict[int, NeighbourEstimate] = {}

    def exo(self, n: int) -> np.ndarray:
        key = (self.omega, self.dt, n)
        m = _EXO_CACHE.get(key)
        if m is None:
            m = exo_propagator(self.omega, n * self.dt)
            _EXO_CACHE[key] = m
        return m

    def err(self, leader: bool, n: int) -> np.ndarray:
        kp, kv = self.gains[leader]
        key = (kp, kv, self.dt, n)
        m = _ERR_CACHE.get(key)
        if m is None:
            m = expm(np.array([[0.0, 1.0], [-kp, -kv]]) * n * self.dt)
            _ERR_CACHE[key] = m
        return m

    def ingest(self, neighbours: dict[int, NeighbourEstimate], comm_ok: bool) -> None:
        """Keep the newest estimate per agent (an out-of-order older one is ignored)."""
        if not comm_ok:
            return
        last = self.last
        for j, e in neighbours.items():
            old = last.get(j)
            if old is None or e.t >= old.t:
                last[j] = e

    def get(self, agent_id: int, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(p, v, ξ) of ``agent_id`` predicted to ``t``; None if never received or older
        than ``max_age`` (the agent then runs without that neighbour: the conservative
        behaviour for a silent or dead neighbour; onboard sensing still feeds the RCBF)."""
        e = self.last.get(agent_id)
        if e is None or t - e.t > self.max_age + 1e-9:
            return None
        n = int(round((t - e.t) / self.dt))
        if n <= 0:
            return e.z1, e.z2, e.xi
        xi = self.exo(n) @ e.xi
        m = self.err(e.is_leader, n)
        e1 = e.z1 - e.xi[0:3]
        e2 = e.z2 - e.xi[3:6]
        return xi[0:3] + m[0, 0] * e1 + m[0, 1] * e2, xi[3:6] + m[1, 0] * e1 + m[1, 1] * e2, xi


class FollowerAgent:
    """Follower: sensing → DESO (§3) + desired-state observer (§4.1) → CLF–RCBF QP (§4.4)."""

    is_leader = False

    def __init__(
        self, sc, agent_id: int, method: str | None = None, seed: int | None = None,
        form: Formation | None = None,
    ) -> None:
        self.sc = sc
        self.id = agent_id
        self.index = sc.index_of(agent_id)
        self.form = form if form is not None else formation_from_scenario(sc)
        self.dt = sc.control_dt
        seed = sc.seed if seed is None else int(seed)
        obs, ctl, veh = sc.observer, sc.controller, sc.vehicle
        self.veh = veh
        self.ctl = ctl
        self.tau_ff = veh.tau_rollpitch_s
        self.set_method(method or ctl.method)
        self.sensor = Sensor(
            self.index, agent_id, sc.n, sc.sensing, sc.formation.sensing_range_m, seed
        )
        rng = np.random.default_rng([seed, agent_id, 0x1E])
        spec = sc.agents[self.index]
        z1 = spec.position + rng.standard_normal(3) * obs.init_pos_error_m
        z2 = spec.velocity + rng.standard_normal(3) * obs.init_vel_error_mps
        self.substeps = obs.substeps
        self.anchor = obs.leader_anchor > 0.0
        beta = tuple(obs.beta)
        self.deso = DESO(
            self.form, self.index, beta, obs.mu, obs.sigma, self.substeps, self.dt,
            sc.unmodeled.ground_effect_height_m, z1, z2, obs.leader_anchor,
            tuple(obs.velocity_gain),
        )
        omega = 2.0 * math.pi * sc.leader_trajectory.frequency_hz
        xi0 = np.concatenate([z1, np.zeros(9)])
        self.ref = DesiredStateObserver(
            self.form, self.index, omega, obs.reference_gain, self.dt, xi0
        )
        lam, ks = ctl.clf_lambda, ctl.ks
        self.pred = _Predictor(
            omega, self.dt, (ks * lam + ctl.kp / ctl.kd, lam + ks),
            (ctl.leader_kp, ctl.leader_kd), sc.communication.max_age_s,
        )
        self.inner = InnerLoopModel(veh, self.dt / self.substeps)
        self.u_lo, self.u_hi = control_box(sc)
        self.qp = SafetyQP(
            sc.n - 1, self.u_lo, self.u_hi, ctl.rho, ctl.clf_c,
        )
        if ctl.tau_safe_s <= 0.0:
            raise ValueError("controller.tau_safe_s must be > 0 for the RCBF (relative degree 1)")
        self.leader_mask = np.zeros(sc.n, dtype=bool)
        self.leader_mask[self.form.leader_idx] = True
        self.ids = sc.ids
        nb = set(self.form.neighbours[self.index])
        self._peers = [
            (j, j in nb, bool(self.leader_mask[j]))
            for j in sorted(nb | set(self.form.leader_idx))
        ]
        self.yaw = 0.0
        self.fallbacks = 0
        self._gains: GainReport | None = None
        self._hold_dropped = sc.sensing.dropout_prob > 0.0
        self._last_seen = np.full(sc.n, -np.inf)
        self._last_rp = np.zeros((sc.n, 3))
        self._last_rv = np.zeros((sc.n, 3))

    @property
    def gains(self) -> GainReport:
        """DESO gain check (errata 7), computed on first use."""
        if self._gains is None:
            obs = self.sc.observer
            self._gains = gain_report(
                self.form, tuple(obs.beta), self.dt, obs.substeps, obs.leader_anchor,
                tuple(obs.velocity_gain),
            )
        return self._gains

    def set_method(self, method: str) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
        self.method = method

    def initial_estimate(self) -> NeighbourEstimate:
        return NeighbourEstimate(
            self.id, 0.0, self.deso.z1.copy(), self.deso.z2.copy(), self.deso.z3.copy(),
            self.ref.xi.copy(), False,
        )

    def step(
        self,
        k: int,
        t: float,
        truth_p: np.ndarray,
        truth_v: np.ndarray,
        neighbours: dict[int, NeighbourEstimate],
        comm_ok: bool = True,
    ) -> AgentOutput:
        ctl = self.ctl
        meas = self.sensor.measure(np.asarray(truth_p, float), np.asarray(truth_v, float))
        rel_p = meas.rel_pos()  # p_j − p_i
        rel_v = meas.rel_vel()
        self.pred.ingest(neighbours, comm_ok)
        nbr_p: dict[int, np.ndarray] = {}
        nbr_v: dict[int, np.ndarray] = {}
        nbr_xi: dict[int, np.ndarray] = {}
        lead_acc: dict[int, np.ndarray] = {}
        for j, is_nbr, is_lead in self._peers:
            got = self.pred.get(self.ids[j], t)
            if got is None:
                continue
            if is_nbr:
                nbr_xi[j] = got[2]
            if is_nbr or (is_lead and self.anchor):
                nbr_p[j], nbr_v[j] = got[0], got[1]
            if is_lead:
                lead_acc[j] = got[2][6:9]
        # --- controller at t_k --------------------------------------------------------
        z1, z2 = self.deso.z1, self.deso.z2
        w_raw = self.deso.lumped()
        # peaking of the high-gain observer: saturate the disturbance estimate used in control
        wn = math.sqrt(float(w_raw @ w_raw))
        w = w_raw * (W_MAX / wn) if wn > W_MAX else w_raw
        e1 = z1 - self.ref.p
        e2 = z2 - self.ref.v
        # acceleration feed-forward taken τ_rp ahead (â* + τ_rp ĵ*): compensates the
        # first-order attitude lag of the inner loop on the moving reference
        a_ff = self.ref.a + self.tau_ff * self.ref.xi[9:12]
        clf = clf_terms(e1, e2, w, a_ff, ctl.kp, ctl.kd, ctl.clf_lambda, ctl.ks)
        # safety pairs: this step's measurements; a pair dropped this step but sensed within
        # SENSE_HOLD_S is extrapolated with its last relative velocity (dropouts must not
        # switch a barrier off)
        valid = meas.valid
        held = None
        if self._hold_dropped:
            self._last_seen[valid] = t
            self._last_rp[valid] = rel_p[valid]
            self._last_rv[valid] = rel_v[valid]
            held = ~valid & (t - self._last_seen <= SENSE_HOLD_S)
            held[self.index] = False
        if held is not None and held.any():
            age = (t - self._last_seen[held])[:, None]
            rp_s, rv_s = rel_p.copy(), rel_v.copy()
            rp_s[held] = self._last_rp[held] + age * self._last_rv[held]
            rv_s[held] = self._last_rv[held]
            sel = np.nonzero(valid | held)[0]
        else:
            rp_s, rv_s = rel_p, rel_v
            sel = np.nonzero(valid)[0]
        dp = -rp_s[sel]  # p_i − p_j
        dv = -rv_s[sel]
        status = AgentStatus(method=self.method, comm_ok=comm_ok, n_sensed=len(sel), V=clf.V)
        tau, dsafe = ctl.tau_safe_s, ctl.d_safe_m
        if self.method == "none":
            u = none_control(clf.u_nom, self.u_lo, self.u_hi)
            if len(sel):
                status.h_min = float(barrier(dp, dv, tau, dsafe).min())
        else:
            h = barrier(dp, dv, tau, dsafe)
            side = tangential_term(dp, h, ctl.deadlock_gain, ctl.deadlock_h_m2)
            if self.method == "apf":
                dd = np.einsum("ij,ij->i", dp, dv) / np.maximum(
                    np.sqrt(np.einsum("ij,ij->i", dp, dp)), 1e-6
                )  # range rate ḋ_ij (negative when closing)
                u = apf_control(
                    clf.u_nom, dp, dd, side, ctl.apf_gain,
                    ctl.apf_velocity_gain, ctl.apf_radius_m, self.u_lo, self.u_hi,
                )
                status.h_min = float(h.min()) if len(h) else float("inf")
            else:
                lm = self.leader_mask[sel]
                share = np.where(lm, 1.0, 0.5)
                a_other = np.zeros((len(sel), 3))
                if lead_acc and np.any(lm):
                    for r in np.nonzero(lm)[0]:
                        a_other[r] = lead_acc.get(int(sel[r]), 0.0)
                # own disturbance in the barrier rows: the estimate saturated at W_SAFE, so a
                # start-up transient of the observer cannot cancel a safety row
                wsn = math.sqrt(float(w @ w))
                w_safe = w * (W_SAFE / wsn) if wsn > W_SAFE else w
                n_hat, rhs, h = rcbf_rows(
                    dp, dv, w_safe, a_other, share, tau, dsafe, ctl.gamma, h=h
                )
                brake = -w - self.qp.brake_gain * z2
                res: QPResult = self.qp.solve(clf.u_nom + side, clf, n_hat, rhs, h, brake)
                u = res.u
                if res.fallback:
                    self.fallbacks += 1
                status.qp_status = res.status
                status.solve_us = res.solve_us
                status.h_min = res.h_min
                status.slack = res.slack
                status.violation = res.violation
        if not np.all(np.isfinite(u)):
            u = np.clip(np.nan_to_num(-w), self.u_lo, self.u_hi)
            self.fallbacks += 1
        status.fallbacks = self.fallbacks
        sp: Setpoint = setpoint_from_accel(u, self.yaw, self.veh)
        # --- observers to t_{k+1} ---------------------------------------------------
        u_sub = self.inner.run(sp, self.substeps)
        self.deso.update(rel_p, rel_v, meas.valid, nbr_p, nbr_v, u_sub)
        self.ref.update(nbr_xi)
        status.n_used = self.deso.n_used
        est = NeighbourEstimate(
            self.id, t + self.dt, self.deso.z1.copy(), self.deso.z2.copy(),
            self.deso.z3.copy(), self.ref.xi.copy(), False,
        )
        return AgentOutput(
            sp.roll, sp.pitch, sp.yaw, sp.thrust_n, sp.q_ned, sp.thrust_norm, u, est, status,
            lumped=w_raw,
        )


class LeaderAgent:
    """Leader: tracks p_L(t) = p_L(0) + A(1 − cos ωt) with its own state (errata 4)."""

    is_leader = True

    def __init__(
        self, sc, agent_id: int, method: str | None = None, seed: int | None = None,
        form: Formation | None = None,
    ) -> None:
        self.sc = sc
        self.id = agent_id
        self.index = sc.index_of(agent_id)
        self.dt = sc.control_dt
        self.veh = sc.vehicle
        ctl = sc.controller
        self.kp, self.kd = ctl.leader_kp, ctl.leader_kd
        lt = sc.leader_trajectory
        self.traj = LeaderTrajectory(
            sc.agents[self.index].position, np.array(lt.amplitude_m), lt.frequency_hz
        )
        self.method = method or ctl.method
        self.u_lo, self.u_hi = control_box(sc)
        self.substeps = sc.observer.substeps
        self.inner = InnerLoopModel(self.veh, self.dt / self.substeps)
        # velocity ESO: v̂' = u + d̂ + l1 (v − v̂),  d̂' = l2 (v − v̂)   (double pole at −5)
        self.l1, self.l2 = 10.0, 25.0
        self.v_hat = sc.agents[self.index].velocity.astype(float).copy()
        self.d_hat = np.zeros(3)
        self.yaw = 0.0
        self.start_time = 0.0
        self.gains = None

    def reference(self, t: float) -> np.ndarray:
        """ξ_L(t) = [p, ṗ, p̈, p⃛] of the leader trajectory; held at p_L(0) before
        ``start_time`` (0 in lockstep; in real time the daemon sets the first whole
        trajectory period after arming, the same for both leaders, so the motion starts
        smoothly and the leaders stay in step)."""
        if t < self.start_time:
            return np.concatenate([self.traj.state(0.0)[0:3], np.zeros(9)])
        return self.traj.state(t)

    def set_method(self, method: str) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
        self.method = method

    def initial_estimate(self) -> NeighbourEstimate:
        spec = self.sc.agents[self.index]
        return NeighbourEstimate(
            self.id, 0.0, spec.position.astype(float).copy(), spec.velocity.astype(float).copy(),
            np.zeros(3), self.traj.state(0.0), True,
        )

    def step(
        self,
        k: int,
        t: float,
        truth_p: np.ndarray,
        truth_v: np.ndarray,
        neighbours: dict[int, NeighbourEstimate],
        comm_ok: bool = True,
    ) -> AgentOutput:
        p = np.asarray(truth_p[self.index], dtype=float)
        v = np.asarray(truth_v[self.index], dtype=float)
        ref = self.reference(t)
        a_ff = ref[6:9] + self.veh.tau_rollpitch_s * ref[9:12]  # lag compensation
        u = a_ff - self.d_hat + self.kp * (ref[0:3] - p) + self.kd * (ref[3:6] - v)
        u = np.clip(u, self.u_lo, self.u_hi)
        sp = setpoint_from_accel(u, self.yaw, self.veh)
        u_sub = self.inner.run(sp, self.substeps)
        # velocity ESO over the period (sub-stepped Euler, measurement held)
        dl = self.dt / self.substeps
        for s in range(self.substeps):
            err = v - self.v_hat
            self.v_hat = self.v_hat + dl * (u_sub[s] + self.d_hat + self.l1 * err)
            self.d_hat = self.d_hat + dl * self.l2 * err
        a = u_sub.mean(axis=0) + self.d_hat
        est = NeighbourEstimate(
            self.id, t + self.dt, p + v * self.dt + 0.5 * a * self.dt**2, v + a * self.dt,
            self.d_hat.copy(), self.reference(t + self.dt), True,
        )
        status = AgentStatus(method=self.method, comm_ok=comm_ok)
        return AgentOutput(
            sp.roll, sp.pitch, sp.yaw, sp.thrust_n, sp.q_ned, sp.thrust_norm, u, est, status,
            lumped=self.d_hat.copy(),
        )


def make_agent(
    sc, agent_id: int, method: str | None = None, seed: int | None = None,
    form: Formation | None = None,
) -> FollowerAgent | LeaderAgent:
    """The agent object for ``agent_id`` (role from the scenario)."""
    cls = LeaderAgent if agent_id in sc.leader_ids else FollowerAgent
    return cls(sc, agent_id, method=method, seed=seed, form=form)


__all__ = [
    "AgentOutput",
    "AgentStatus",
    "FollowerAgent",
    "LeaderAgent",
    "NeighbourEstimate",
    "make_agent",
    "accel_from_attitude",
]
