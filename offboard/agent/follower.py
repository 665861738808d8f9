"""Follower agent: sensing → DESO (§3) + desired-state observer (§4.1) → safety filter (§4.4).

Step k: sense (t_k) → predict neighbours to t_k → nominal controller on (z(t_k), ξ̂(t_k))
→ safety filter of the current method → setpoint → inner-loop model → DESO and
desired-state observer advanced to t_{k+1} → publish.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

import numpy as np

from offboard.agent.base import CLIP_TOL, AgentBase
from offboard.agent.detour import Detour
from offboard.agent.fence_swap import swap_fence
from offboard.agent.governor import governor_for, log_governor
from offboard.agent.guard import InFlightGuard
from offboard.agent.pair_inputs import PairInputs
from offboard.agent.peers import peer_ids
from offboard.agent.shares import ShareRule
from offboard.agent.takeoff import follower_xi
from offboard.agent.unsensed import PredictedPairs, UnsensedNeighbours
from offboard.estimation.bearing import Formation, formation_from_scenario
from offboard.estimation.deso import DESO
from offboard.estimation.deso_gains import GainReport, formation_gain_report
from offboard.estimation.formation_frame import FormationFrameObserver, formation_frame_observer
from offboard.estimation.neighbour_accel import NeighbourAccel
from offboard.estimation.peer_table import EstimateBatch
from offboard.estimation.predictor import NeighbourPredictor
from offboard.estimation.reference import DesiredStateObserver, xi_at_rest
from offboard.estimation.sensing import DropoutHold, Sensor
from offboard.estimation.sensing_kernel import pair_rows
from offboard.inner_loop.attitude import Setpoint
from offboard.records import AgentOutput, AgentStatus, NeighbourEstimate
from offboard.safety.base import SafetyInput, SafetyOutput, saturate_norm
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.front import DcbfFront, unsensed_rows
from offboard.safety.dcbf.world_rows import WorldPlanes
from offboard.safety.filter import make_filters
from offboard.safety.rcbf.clf_rcbf import ClfTerms, clf_terms_of_reference
from swarm_common.enums import Method, QPStatus
from swarm_common.fastnp import f64, finite, rows3, vec3
from swarm_common.scenario.mission_check import yaws as mission_yaws
from swarm_common.scenario.model import Scenario
from swarm_common.scenario.safety_check import pair_terms
from swarm_common.world.config import Geofence

W_MAX = 2.0  # m/s², bound on the lumped-disturbance estimate used by the controller
SENSE_HOLD_S = 0.2  # s, a dropped pair's last measurement is extrapolated this long
MAX_COAST_PERIODS = 50  # periods a missed-step catch-up advances at most (1 s at 50 Hz)


class FollowerAgent(AgentBase):
    """Follower: sensing → DESO (§3) + desired-state observer (§4.1) → CLF–RCBF QP (§4.4)."""

    is_leader = False

    def __init__(
        self, sc: Scenario, agent_id: int, method: Method | str | None = None,
        seed: int | None = None, form: Formation | None = None,
    ) -> None:
        super().__init__(sc, agent_id, method)
        self.form = form if form is not None else formation_from_scenario(sc)
        seed = sc.seed if seed is None else int(seed)
        obs, ctl = sc.observer, sc.controller
        self.ctl = ctl
        self.tau_ff = self.veh.tau_rollpitch_s
        self.sensor = Sensor(
            self.index, agent_id, sc.n, sc.sensing, sc.formation.sensing_range_m, seed
        )
        rng = np.random.default_rng([seed, agent_id, 0x1E])
        spec = sc.agents[self.index]
        z1 = spec.position + rng.standard_normal(3) * obs.init_pos_error_m
        z2 = spec.velocity + rng.standard_normal(3) * obs.init_vel_error_mps
        self.deso = DESO(
            self.form, self.index, tuple(obs.beta), obs.mu, obs.sigma, self.substeps, self.dt,
            sc.unmodeled.ground_effect_height_m, z1, z2, obs.leader_anchor,
            tuple(obs.velocity_gain),
        )
        # the leaders fly the governed trajectory (offboard.agent.governor, docs/saturation.md)
        self.governor = governor_for(sc)
        log_governor(self.governor, agent_id)
        omega = self.governor.omega
        self.ref: DesiredStateObserver | FormationFrameObserver = DesiredStateObserver(
            self.form, self.index, omega, obs.reference_gain, self.dt, xi_at_rest(z1)
        )
        if mission_yaws(sc):  # the bearings turn with the formation (docs/missions.md)
            self.ref = formation_frame_observer(sc, self.ref)
        lam, ks = ctl.clf_lambda, ctl.ks
        self.pred = NeighbourPredictor(
            sc.ids, omega, self.dt, (ks * lam + ctl.kp / ctl.kd, lam + ks),
            (ctl.leader_kp, ctl.leader_kd), sc.communication.max_age_s,
            a_max=math.sqrt(3.0) * ctl.u_max_mps2 + W_MAX,
        )
        self.leader_mask = np.zeros(sc.n, dtype=bool)
        self.leader_mask[self.form.leader_idx] = True
        self.filters = make_filters(ctl, self.u_lo, self.u_hi, self.leader_mask)
        dcbf = self.filters.get(Method.DCBF)
        # the world's half-spaces (obstacles, geofence) as dcbf rows (docs/world.md)
        self._world = (None if sc.world.empty or not isinstance(dcbf, DcbfFilter)
                       else WorldPlanes(sc.world, sc.formation.sensing_range_m))
        if isinstance(dcbf, DcbfFilter):
            dcbf.configure(self.veh, self.dt,
                           0 if self._world is None else self._world.capacity)
        # out of a pocket of obstacles when the deadlock detector finds it stuck
        self.detour = None if self._world is None else Detour(self._world, self.index)
        # the acceleration estimate reads the predictor's table (one ingest fills both)
        self.acc_est = NeighbourAccel(sc.ids, ctl.u_max_mps2 + W_MAX, table=self.pred.table)
        # anti-windup box of the nominal law per method (docs/saturation.md §2): the box of
        # the box methods; none for dcbf, whose polytope the governor's reserve keeps free
        self.aw_box: dict[Method, tuple[np.ndarray, np.ndarray] | None] = {
            m: (self.u_lo, self.u_hi) for m in Method
        }
        self.aw_box[Method.DCBF] = None
        self.u_prev = np.zeros(3)
        self.last_k: int | None = None  # the step of the previous call (coasting, above)
        self._span = 1  # control periods since the step before (_coast_missed)
        self.last_sp: Setpoint | None = None
        self.a_real = np.zeros(3)  # inner-loop model's realised virtual control (m/s²)
        self.a_mean = np.zeros(3)  # ... its mean over the last control period
        # scenario indices of the agents whose estimates this follower reads (its daemon
        # subscribes to them only): what it takes from an in-process batch, and predicts
        self._peer_idx = np.array(
            sorted(self.form.index_of(a) for a in peer_ids(self.form, agent_id)), dtype=np.int64
        )
        # the ones predicted to t_k for the observers: graph neighbours and the leaders
        # among the peers, the observer's anchors (offboard.agent.peers)
        lead_peers = self.form.anchor_leaders(self.index)
        nb = set(self.form.neighbours[self.index])
        self._predict_idx = np.array(sorted(nb | set(lead_peers)), dtype=np.int64)
        self.pair_inputs = PairInputs(lead_peers)  # part-by-part filters' pairs
        # neighbours predicted into sensing range but not sensed (dcbf, docs/safety.md §5c)
        # the in-flight alarms and the fallback (offboard.agent.guard, docs/safety.md)
        self.guard = InFlightGuard(sc, self.index, self._predict_idx, self.u_lo, self.u_hi)
        self.unsensed = UnsensedNeighbours(
            self.pred, self.index, sc.n, sc.formation.sensing_range_m, ctl.tau_safe_s,
            pair_terms(sc), 2.0 * math.sqrt(3.0) * ctl.u_max_mps2 * self.dt)
        # who takes a pair's whole avoidance budget in the dcbf filter
        self.shares = ShareRule(self.pred, self.leader_mask, self.dt)
        self.fallbacks = 0
        self._airborne = False  # latched once the altitude estimate reached the ground floor
        self._gains: GainReport | None = None
        self.hold = DropoutHold(sc.n, self.index, SENSE_HOLD_S, sc.sensing.dropout_prob > 0.0)
        # the sensed pairs' Δp, Δv of the step (the filter reads them within the step)
        self._dp, self._dv = np.zeros((sc.n, 3)), np.zeros((sc.n, 3))
        # the dcbf step up to the QP in one compiled call (offboard.safety.dcbf.front)
        self._front = (DcbfFront(self.deso, dcbf, self.acc_est, ctl, self.tau_ff, W_MAX,
                                 self._dp, self._dv)
                       if isinstance(dcbf, DcbfFilter) else None)

    def replace_fence(self, fence: Geofence) -> bool:
        """Keep ``fence`` instead of the scenario's from the next step on, the obstacles as
        they are: the fence uploaded to the vehicle (offboard.daemon.fence_sync). False
        without a dcbf filter, the only one with world rows."""
        dcbf = self.filters.get(Method.DCBF)
        if not isinstance(dcbf, DcbfFilter) or self._front is None:
            return False
        self._world = swap_fence(self._world, dcbf, self._front, fence,
                                 self.sc.formation.sensing_range_m)
        if self.detour is None:
            self.detour = Detour(self._world, self.index)
        return True

    @property
    def gains(self) -> GainReport:
        """DESO gain check (Departure 7), computed on first use
        (:func:`~offboard.estimation.deso_gains.formation_gain_report`)."""
        if self._gains is None:
            self._gains = formation_gain_report(self.form, self.sc.observer, self.dt)
        return self._gains

    def initial_estimate(self) -> NeighbourEstimate:
        return self._estimate(0.0)

    def step(
        self,
        k: int,
        t: float,
        truth_p: np.ndarray,
        truth_v: np.ndarray,
        neighbours: Mapping[int, NeighbourEstimate] | EstimateBatch,
        comm_ok: bool = True,
    ) -> AgentOutput:
        """One step (module docstring). ``neighbours``: the estimates received (by agent
        id), or the in-process runner's batch of every agent's, of which this follower
        takes its peers' rows (nothing while the link is down, as a daemon then receives
        nothing)."""
        self._coast_missed(k, t)
        meas = self.sensor.measure(truth_p, truth_v)  # valid within this step
        rel_p = meas.rel_pos()  # p_j − p_i
        rel_v = meas.rel_vel()
        if not isinstance(neighbours, EstimateBatch):
            self.pred.ingest(neighbours, comm_ok)  # the acceleration slots too
        elif comm_ok:
            self.pred.ingest_batch(neighbours, self._peer_idx, True)
        rows, have = self.pred.predict_rows(self._predict_idx, t)
        own_p, own_v = truth_p[self.index], truth_v[self.index]  # its odometry
        # --- controller at t_k --------------------------------------------------------
        sel, rp, rv = self.hold.pairs(t, meas.valid, rel_p, rel_v)
        alarms = self.guard.check(t, self.deso.z1, self.deso.z2, rows, have, rel_p, meas.valid,
                                  sel, rp, rv)
        extra = (self.unsensed.pairs(t, sel, self.deso.z1, self.deso.z2)
                 if self.method == Method.DCBF else None)
        w_raw, w, v_clf, u_nom, res = self._filter_step(t, sel, rp, rv, rows, have, extra,
                                                        (own_p, own_v))
        status = AgentStatus(method=self.method, comm_ok=comm_ok, n_sensed=len(sel), V=v_clf,
                             alarms=int(alarms), u_nom=u_nom)
        u = self._use_filter_output(res, w, status)
        stuck = self.guard.liveness(t, self.deso.z1, self.ref.xi,
                                    res.qp_status is not QPStatus.INACTIVE,
                                    self.in_formation_phase(t))
        status.alarms |= int(stuck)
        if stuck and self.detour is not None and not self.detour.active(t):
            self.detour.start(t, own_p, self.ref.xi[0:3])
        if self.landing is not None:
            u = self.landed_idle(t, float(self.deso.z1[2]), u)
        u = self.on_pad_floor(t, float(self.deso.z1[2]), u)
        u = self.guard.command(t, own_p, own_v, u, rp, sel)
        # setpoint, the inner-loop model's realised control over the period (sub-steps)
        # and their mean, whether the setpoint clips u: one compiled call
        sp, u_sub, status.input_clipped, a_mean = self.inner.command(
            u, self.yaw, self.substeps, CLIP_TOL
        )
        # --- observers to t_{k+1} ---------------------------------------------------
        self.last_sp = sp
        self.u_prev, self.a_real, self.a_mean = u, u_sub[-1].copy(), a_mean
        self.deso.update(rel_p, rel_v, meas.valid, rows, have, u_sub)
        self.ref.update(rows, have)
        status.n_used = self.deso.n_used
        est = self.guard.estimate(self._estimate(t + self.dt), own_p, own_v)
        return self._output(sp, u, est, status, w_raw)

    # -- the named parts of the step --------------------------------------------------
    def _coast_missed(self, k: int, t: float) -> None:
        """Advance the observers over control periods that had no step (a lost ODOMETRY
        in real time: step k follows step k − m, m > 1). The DESO and the desired-state
        observer each advance exactly one period per step, so without this every lost
        stamp left them a period behind the vehicle. For each missed period the inner-loop
        model applies the last setpoint (what the vehicle kept flying), the DESO
        dead-reckons with it (:meth:`~offboard.estimation.deso.DESO.coast`) and ξ̂ is advanced with
        the neighbours' predictions for that period. The dcbf filter's inputs then span
        the m periods too: the realised acceleration now, its mean since the step before,
        and the relative-acceleration difference over m periods
        (:meth:`~offboard.safety.dcbf.filter.DcbfFilter.set_span`). In process and in lockstep
        k always follows k − 1, so this never runs there (bit-identical runs)."""
        last, self.last_k = self.last_k, k
        if last is None or self.last_sp is None or k <= last + 1:
            if self._span != 1:
                self._set_span(1)
            return
        gap = k - last - 1
        missed = min(gap, MAX_COAST_PERIODS)
        total = np.array(self.a_mean, dtype=np.float64)  # the period after step k − m
        for m in range(missed, 0, -1):  # missed ≥ 1: u_sub is the last coasted period's
            u_sub = self.inner.run(self.last_sp, self.substeps)
            total += u_sub.mean(axis=0)
            self.deso.coast(u_sub)
            self.ref.update(*self.pred.predict_rows(self._predict_idx, t - m * self.dt))
        self.a_real = u_sub[-1].copy()
        self.a_mean = total / (missed + 1)
        self._set_span(missed + 1, forget=gap > missed)

    def _set_span(self, periods: int, forget: bool = False) -> None:
        """The dcbf filter's span to the step before (:meth:`_coast_missed`)."""
        self._span = periods
        dcbf = self.filters.get(Method.DCBF)
        if isinstance(dcbf, DcbfFilter):
            dcbf.set_span(periods)
            if forget:
                dcbf.forget_history()

    def _filter_step(
        self, t: float, sel: np.ndarray, rp: np.ndarray, rv: np.ndarray, rows: np.ndarray,
        have: np.ndarray, extra: PredictedPairs | None, odo: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, SafetyOutput]:
        """The step from the state to the filter's output: (w_raw, w, V, u_nom, output).
        The dcbf filter's in one compiled call (:meth:`_front_step`, with the own odometry
        ``odo`` (p (m), v (m/s)) for the world's rows), the others' part by part
        (:meth:`_composed_step`)."""
        if self.method == Method.DCBF and self._front is not None:
            return self._front_step(self._front, t, sel, rp, rv, extra, odo)
        return self._composed_step(t, sel, rp, rv, rows, have, extra)

    def _composed_step(
        self, t: float, sel: np.ndarray, rp: np.ndarray, rv: np.ndarray, rows: np.ndarray,
        have: np.ndarray, extra: PredictedPairs | None,
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, SafetyOutput]:
        """The step from the state to the filter's output, part by part: (w_raw, w, V,
        u_nom, output). ``w_raw`` is the lumped-disturbance estimate, ``w`` its
        saturation."""
        w_raw = self.deso.lumped()
        # peaking of the high-gain observer: saturate the disturbance estimate used in control
        w = saturate_norm(w_raw, W_MAX)
        clf = self._nominal(w, t)
        m = len(sel)
        dp, dv = self._dp[:m], self._dv[:m]  # Δp = p_i − p_j, Δv = v_i − v_j, written here
        pair_rows(sel, rows3(rp), rows3(rv), dp, dv)
        x = self._safety_input(t, clf, w, sel, dp, dv, rows, have, extra)
        return w_raw, w, clf.V, clf.u_nom, self.filters[self.method].apply(x)

    def _front_step(
        self, front: DcbfFront, t: float, sel: np.ndarray, rp: np.ndarray, rv: np.ndarray,
        extra: PredictedPairs | None, odo: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, SafetyOutput]:
        """The dcbf filter's step in one compiled call (:mod:`offboard.safety.dcbf.front`):
        the sensed pairs, then ``extra``, the neighbours predicted into range but not
        sensed. A step the shortcut settles reports the call's time as ``solve_us``."""
        since, others_heard = self.shares.silence(t)
        t0 = time.perf_counter()
        floor = self._ground_floor()
        xi = f64(self._reference_xi(t))
        # the groups as plain tuples in their NamedTuples' order (DcbfFront.run)
        lumped, w, clf, k, h_min, held, u_try = front.run(
            xi, (sel, rows3(rp), rows3(rv)),
            (self.shares.mask(), self.pred.table.t, since, others_heard),
            (vec3(self.a_real), vec3(self.u_prev), vec3(self.a_mean)),
            floor, unsensed_rows(extra),
        )
        if self._world is not None and floor is not None:  # airborne, not landing
            k_pairs = k
            k = front.filt.add_world_rows(self._world, k, odo[0], odo[1], self.a_real, w)
            world_rows = k > k_pairs
        else:
            world_rows = False
        res = front.solve(u_try, clf, k, h_min, w, held, t0, world_rows, odo[1], self.a_real,
                          xi)
        return lumped[1], w, float(clf[0]), clf[5:8], res

    def _safety_input(
        self, t: float, clf: ClfTerms, w: np.ndarray, sel: np.ndarray, dp: np.ndarray,
        dv: np.ndarray, rows: np.ndarray, have: np.ndarray, extra: PredictedPairs | None,
    ) -> SafetyInput:
        """The filter's input: the sensed pairs (Δp = p_i − p_j, Δv), and ``extra``, the
        neighbours that are not sensed now but predicted (:class:`UnsensedNeighbours`)."""
        sel, dp, dv, margin, predicted = self.pair_inputs.pairs(sel, dp, dv, extra)
        # only the dcbf filter reads the share mask (rcbf keeps the paper's shares)
        full = self.shares.full(sel, t) if self.method == Method.DCBF else None
        return SafetyInput(
            clf, w, self.deso.z2, dp, dv, sel,
            self.pair_inputs.leader_accels(self.method, rows, have), self.a_real,
            self.u_prev, self.a_mean, self.acc_est.rows(sel), full, self.deso.z1,
            self._ground_floor(), margin, predicted,
        )

    def _ground_floor(self) -> float | None:
        """The dcbf ground barrier's floor (m) once this follower has been above it, None
        before (ground start) and while landing (docs/safety.md §7)."""
        floor = self.ctl.dcbf_ground_clearance_m
        if self.landing is not None or floor <= 0.0:
            return None
        if not self._airborne and float(self.deso.z1[2]) >= floor:
            self._airborne = True
        return floor if self._airborne else None

    def _nominal(self, w: np.ndarray, t: float) -> ClfTerms:
        """CLF terms and nominal control on (z(t_k), ξ̂(t_k)) (§4.2, Departure 10), with the
        acceleration feed-forward taken τ_rp ahead (â* + τ_rp ĵ*): it compensates the
        first-order attitude lag of the inner loop on the moving reference."""
        ctl = self.ctl
        return clf_terms_of_reference(
            self.deso.z1, self.deso.z2, self._reference_xi(t), self.tau_ff, w, ctl.kp, ctl.kd,
            ctl.clf_lambda, ctl.ks, box=self.aw_box[self.method],
        )

    def _reference_xi(self, t: float) -> np.ndarray:
        """The desired state the nominal law tracks at t: the landing plan's once landing,
        the take-off plan's while taking off, else the observer's ξ̂ (12,)."""
        if self.landing is not None:  # offboard.agent.landing: the plan replaces ξ̂
            return self.landing.xi(t)
        if self.takeoff is not None and self.takeoff_clock(t) < self.takeoff.t_blend:
            # offboard.agent.takeoff (at rest on the pad while held for the take-off command)
            return follower_xi(self.takeoff, self.index, self.takeoff_clock(t), self.ref.xi)
        if self.detour is not None:  # offboard.agent.detour: out of a pocket of obstacles
            return self.detour.reference(t, self.ref.xi)
        return self.ref.xi

    def _use_filter_output(
        self, res: SafetyOutput, w: np.ndarray, status: AgentStatus
    ) -> np.ndarray:
        """The filter's u, recorded in ``status`` with the correction ‖u − u_nom‖ from its
        nominal control ``status.u_nom`` (m/s²); a non-finite u brakes on −w (the saturated
        disturbance estimate; a fallback)."""
        u = res.u
        if res.fallback:
            self.fallbacks += 1
        if not finite(u):
            u = np.clip(np.nan_to_num(-w), self.u_lo, self.u_hi)
            self.fallbacks += 1
        status.fallbacks = self.fallbacks
        res.report_into(status, u)
        return u

    def current_reference(self, t: float) -> np.ndarray:
        """The landing reference once landing, else the observer's ξ̂ (valid at its last
        update time; ``t`` is used only by the landing reference)."""
        if self.landing is not None:
            return self.landing.xi(t)
        return self.ref.xi.copy()

    def _estimate(self, t: float) -> NeighbourEstimate:
        """What this agent publishes, valid at ``t``: the DESO's state arrays themselves,
        which it replaces each period and never writes in place (no copies)."""
        d = self.deso
        return NeighbourEstimate(
            self.id, t, d.z1, d.z2, d.z3, self.current_reference(t), False,
            cooperative=self.cooperative,
        )

