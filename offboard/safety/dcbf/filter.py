"""``Method.DCBF``: the sampled-data CBF safety filter (docs/safety.md).

Per step: the barrier rows of :func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel` on the
relative state predicted one attitude lag plus one control period ahead, from the
inner-loop model's realised acceleration and the other agents' estimated actual
accelerations, in the QP :class:`offboard.safety.dcbf.qp.DcbfQP` over the realisable
input set. A follower reaches
them through :mod:`offboard.safety.dcbf.front` (one compiled call from its state);
:class:`DcbfFilter` keeps the QP, the lag tables, the per-pair state and the row buffers.
"""

from __future__ import annotations

import time

import numpy as np

from offboard.safety.base import W_SAFE, SafetyFilter, SafetyInput, SafetyOutput, saturate_norm
from offboard.safety.dcbf.active_rows import RowsOf, WorldOf, active_rows
from offboard.safety.dcbf.model import LagCoefficients, ProjectedInputSet
from offboard.safety.dcbf.qp import DcbfQP
from offboard.safety.dcbf.speed_rows import MAX_CUTS, TOL, TransientLimit
from offboard.safety.dcbf.step_kernel import (
    NO_ALT_G,
    NO_ALT_RHS,
    P_ALT_ERR,
    P_DT,
    P_GROUND_ERR,
    P_TAU,
    GroundInput,
    OwnMotion,
    PairRows,
    RowsOut,
    RowsState,
    dcbf_filter_rows_into,
    dcbf_params,
)
from offboard.safety.dcbf.trust import TrustRegion
from offboard.safety.dcbf.world_rows import WorldPlanes, plane_rows_into
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from swarm_common.enums import Method, QPStatus
from swarm_common.fastnp import f64, rows3, vec3
from swarm_common.scenario.model import ControllerConfig, VehicleConfig

# rows the QP is first built with (it grows on demand,
# offboard.safety.rcbf.clf_rcbf._ClfRowsQP.fit_rows):
# 8 pairs and the ground, so up to 9 agents never grow
QP_INITIAL_ROWS = 18
REL_ACC_SMOOTH = 0.5  # low-pass weight of the previous relative-acceleration estimate
# ground barrier (offboard.safety.dcbf.kernel.ground_rows_kernel): its class-K gain (1/s)
# and the bound on the error of the predicted own vertical acceleration (m/s²): thrust lag
# τ_F = 0.03 s makes the vertical channel fast, and the error is the disturbance
# estimate's (saturated at W_SAFE) plus the tilt–thrust coupling; at rest the floor is
# kept by h_g ≥ ē(T+τ)/γ
GROUND_GAMMA = 2.0
GROUND_ACCEL_ERR = 1.0
# the world's rows (offboard.safety.dcbf.world_rows): their class-K gain (1/s); the error
# bound on the predicted own acceleration is the ground's, along every axis (the pair rows'
# ē also covers the other agent's unknown acceleration, which a static surface has not).
# At rest a plane is kept at h ≥ ē(T+τ)/γ + ē(T²/2+τT): 0.39 m in cube8
WORLD_GAMMA = 4.0
SLACK_TOL = 1e-6  # m/s²: the speed rows stay when they add no more than this to σ
NO_ROWS = np.zeros(0, dtype=np.int64)  # no pair rows of that kind (never written)
NO_CLF = np.zeros(3)  # L_gV of a solve without the CLF row's pull (never written)


def input_set_of(ctl: ControllerConfig, veh: VehicleConfig) -> ProjectedInputSet:
    """The realisable input polytope of ``[vehicle]`` with ``ctl.dcbf_cone_sides`` sides."""
    return ProjectedInputSet.from_vehicle(
        veh.mass_kg, veh.gravity_mps2, veh.thrust_max_n, veh.tilt_max_deg, ctl.u_max_mps2,
        ctl.dcbf_cone_sides,
    )


class DcbfFilter(SafetyFilter):
    """Sampled-data CBF over the input polytope; needs :meth:`configure` before use."""

    method = Method.DCBF

    def __init__(
        self, ctl: ControllerConfig, u_lo: np.ndarray, u_hi: np.ndarray, leader_mask: np.ndarray
    ) -> None:
        super().__init__(ctl, u_lo, u_hi, leader_mask)
        if ctl.tau_safe_s <= 0.0:
            raise ValueError("controller.tau_safe_s must be > 0 for the DCBF (relative degree 1)")
        self.qp: DcbfQP | None = None
        self.lag: LagCoefficients | None = None
        self.brake_gain = 2.0
        n = len(leader_mask)
        # per scenario index j: Δv sensed the step before (valid where _prev_ok) and the
        # low-passed relative acceleration (valid where _rel_ok), read and updated by the
        # compiled rows (offboard.safety.dcbf.kernel.other_term_kernel)
        self._prev_dv = np.zeros((n, 3))
        self._prev_ok = np.zeros(n, dtype=bool)
        self._rel_acc = np.zeros((n, 3))
        self._rel_ok = np.zeros(n, dtype=bool)
        self._params = np.zeros(0)  # the compiled rows' parameters, set by configure
        self._dt = 0.0  # control period (s), set by configure
        # the rows' buffers (two per other agent, two for the ground) and the sidestep,
        # rewritten each step: the QP reads them within the step
        self._g = np.zeros((2 * n + 2, 3))
        self._rhs = np.zeros(2 * n + 2)
        self._side = np.zeros(3)
        # the trust region (offboard.safety.dcbf.trust; configure, when the scenario sets
        # dcbf_trust_jump_mps2): its QP, the tight rows' buffers and per-step counts of
        # the steps it solved, those that fell back to the full rows and those where a0
        # was outside its table
        self.trust: TrustRegion | None = None
        self.tight_qp: DcbfQP | None = None
        self._g_alt, self._rhs_alt = NO_ALT_G, NO_ALT_RHS
        self.trust_counts = np.zeros(3, dtype=np.int64)
        # where the step's rows come from, for the active rows it reports (active_rows): the
        # pair rows' scenario indices (sensed, then predicted), the ground's two rows, and
        # the world's (its planes, their first row, the agent's position)
        self._rows_of: RowsOf = (NO_ROWS, NO_ROWS, False)
        self._world_of: WorldOf | None = None
        # the transient speed limit (offboard.safety.dcbf.speed_rows; configure, when the
        # scenario sets max_transient_speed_mps) and the first of its rows this step
        self.speed: TransientLimit | None = None
        self._speed_from = -1

    def note_rows(self, sensed: np.ndarray, predicted: np.ndarray, ground: bool) -> None:
        """The step's pair rows are those of the agents of scenario indices ``sensed``, then
        ``predicted``, followed by the ground's two rows when ``ground`` (the layout of
        :func:`~offboard.safety.dcbf.step_kernel.dcbf_filter_rows_into`); no world rows
        until :meth:`add_world_rows`. Only the report of the active rows reads it."""
        self._rows_of = (sensed, predicted, ground)
        self._world_of = None
        self._speed_from = -1

    def configure(self, veh: VehicleConfig, dt: float, world_planes: int = 0) -> None:
        """Vehicle limits and lags (τ_rp horizontally, τ_F vertically), control period dt (s);
        the prediction horizon is T = τ_rp + dt. ``world_planes``: room for this many
        half-spaces of the world (:meth:`add_world_rows`), two rows each."""
        uset = input_set_of(self.ctl, veh)
        # two per other agent, two for the ground, two per half-space of the world
        rows = 2 * (len(self.leader_mask) - 1) + 2 + 2 * world_planes
        # the speed rows: MAX_CUTS tangent planes and the inner cube's six
        speed = MAX_CUTS + 6 if self.ctl.max_transient_speed_mps > 0.0 else 0
        rows += speed
        if world_planes or speed:
            self._g = np.zeros((len(self._g) + 2 * world_planes + speed, 3))
            self._rhs = np.zeros(len(self._g))
        self.qp = DcbfQP(min(rows, QP_INITIAL_ROWS), uset, self.ctl.rho, self.ctl.clf_c,
                         limit=rows, solver=self.ctl.qp_solver)
        tau = np.array([veh.tau_rollpitch_s, veh.tau_rollpitch_s, veh.tau_thrust_s])
        self.lag = LagCoefficients.of(tau, veh.tau_rollpitch_s + dt)
        jump = self.ctl.dcbf_trust_jump_mps2
        if jump > 0.0:
            self.trust = TrustRegion(jump, self.ctl.dcbf_trust_error_mps2,
                                     self.ctl.dcbf_accel_error_mps2, veh, uset, self.lag.T)
            self.tight_qp = DcbfQP(min(rows, QP_INITIAL_ROWS), uset, self.ctl.rho,
                                   self.ctl.clf_c, limit=rows, solver=self.ctl.qp_solver,
                                   trust=True)
            self._g_alt, self._rhs_alt = np.zeros_like(self._g), np.zeros_like(self._rhs)
        self._dt = float(dt)
        ctl = self.ctl
        self._params = dcbf_params(
            ctl.tau_safe_s, ctl.d_safe_m, ctl.dcbf_gamma_lin, ctl.dcbf_gamma_cubic,
            ctl.dcbf_accel_error_mps2, ctl.deadlock_gain, ctl.deadlock_h_m2, dt,
            REL_ACC_SMOOTH, GROUND_GAMMA, GROUND_ACCEL_ERR, self.lag.T,
            vertical_scale=ctl.dcbf_vertical_scale,
        )
        if speed:
            self.speed = TransientLimit(ctl.max_transient_speed_mps, self.lag,
                                        float(self._params[P_GROUND_ERR]), uset)

    def prepare_trust(self, a0: np.ndarray, u_prev: np.ndarray) -> None:
        """Before a step's rows: the trust region's bound J (:meth:`TrustRegion.level`,
        from the previous command ``u_prev``) and tight margin ē(J, a0) for realised
        acceleration ``a0`` (m/s²) into the rows' parameters (0: no tight rows this step),
        its box ``a0 ± J`` into the tight QP. Nothing without a trust region."""
        if self.trust is None or self.tight_qp is None:
            return
        jump = self.trust.level(a0, u_prev)
        e = self.trust.margin(a0, jump)
        self._params[P_ALT_ERR] = e
        if e > 0.0:
            self.tight_qp.set_trust(a0 - jump, a0 + jump)

    def set_span(self, periods: int) -> None:
        """The step before was ``periods`` control periods ago (1 in process and in
        lockstep; more where a real-time daemon missed steps, whose vehicle meanwhile
        flew the last command: :meth:`offboard.agent.follower.FollowerAgent._coast_missed`).
        The relative acceleration's finite difference then spans that time, and the
        caller's ``a_mean`` the same span: dividing by one period made a step after m
        missed ones see an m-fold relative acceleration, spurious barrier rows and
        saturated escapes (docs/faults.md)."""
        if self.lag is None:
            raise RuntimeError("DcbfFilter.configure(vehicle, dt) was not called")
        self._params[P_DT] = self._dt * periods

    def forget_history(self) -> None:
        """No pair's relative velocity of the step before is used (a gap too long to
        difference across): each pair starts afresh, from the broadcast estimates."""
        self._prev_ok[:] = False

    def apply(self, x: SafetyInput) -> SafetyOutput:
        """The barrier rows of this step (one compiled call,
        :func:`offboard.safety.dcbf.step_kernel.dcbf_filter_rows_into`) in the QP, from a
        :class:`SafetyInput` whose nominal control is already made. A follower's step
        does not come here: it makes the same rows with the same kernel inside the one
        compiled call of :func:`offboard.safety.dcbf.front.dcbf_front_into`, from its
        state, then :meth:`solve_rows`.

        The other agent's acceleration enters the rows as ``a_j − w_i`` (the own lumped
        disturbance is not lagged, so it is an offset of the other's acceleration). Where
        the pair was sensed the step before it comes from the sensed relative velocity:
        ``Δa = (Δv_k − Δv_{k−1})/dt = a_i − a_j`` over the last period with
        ``a_i = ā_i + w_i`` (ā_i the inner-loop model's mean realised control), so
        ``a_j − w_i = ā_i − Δa``, low-passed, with no disturbance estimate needed.
        Otherwise it is the other's broadcast-velocity estimate minus the own estimate
        saturated at W_SAFE."""
        if self.qp is None or self.lag is None:
            raise RuntimeError("DcbfFilter.configure(vehicle, dt) was not called")
        n = len(x.pairs)
        lm = self.leader_mask[x.pairs] if x.full_share is None else x.full_share
        # saturated: a start-up transient of the observer cannot cancel a row
        w_safe = saturate_norm(x.w, W_SAFE)
        ground = x.floor_m is not None and x.z1 is not None  # airborne: the ground barrier
        rows = PairRows(
            rows3(x.dp), rows3(x.dv), np.asarray(x.pairs, dtype=np.int64),
            np.asarray(lm, dtype=np.bool_),
            np.zeros(n, dtype=np.bool_) if x.predicted is None
            else np.asarray(x.predicted, dtype=np.bool_),
            np.zeros(n) if x.margin is None else f64(x.margin),
            np.zeros((n, 3)) if x.other_acc is None else rows3(x.other_acc),
        )
        own = OwnMotion(vec3(x.a_real), vec3(x.u_prev), vec3(x.a_mean), vec3(w_safe))
        floor = GroundInput(
            ground, float(x.z1[2]) if ground and x.z1 is not None else 0.0, float(x.z2[2]),
            float(x.floor_m) if ground and x.floor_m is not None else 0.0,
        )
        self.note_rows(rows.pairs, NO_ROWS, ground)
        self.prepare_trust(own.a_real, own.u_prev)
        k, h_min = dcbf_filter_rows_into(rows, own, floor, self.rows_state(), self.rows_out())
        return self.solve_rows(x.clf.u_nom + self._side, x.clf, k, h_min, x.w, x.z2)

    def reserve_world(self, more_planes: int) -> bool:
        """Room for ``more_planes`` half-spaces of the world beyond those :meth:`configure`
        made room for (a fence with more faces than the scenario's, uploaded in flight):
        two rows each in the row buffers and in the QPs' growth limit. True when the
        buffers were replaced, so that a caller holding :meth:`rows_out` takes them again."""
        if self.qp is None:
            raise RuntimeError("DcbfFilter.configure(vehicle, dt) was not called")
        if more_planes <= 0:
            return False
        for qp in (self.qp, self.tight_qp):
            if qp is not None:
                qp.limit += 2 * more_planes
        self._g = np.zeros((len(self._g) + 2 * more_planes, 3))
        self._rhs = np.zeros(len(self._g))
        if self.tight_qp is not None:
            self._g_alt, self._rhs_alt = np.zeros_like(self._g), np.zeros_like(self._rhs)
        return True

    def add_world_rows(self, planes: WorldPlanes, k: int, p: np.ndarray, v: np.ndarray,
                       a0: np.ndarray, w: np.ndarray) -> int:
        """Append the rows of the world's half-spaces for an agent at ``p`` (m) with
        velocity ``v`` (m/s), realised acceleration ``a0`` and disturbance estimate ``w``
        (m/s², saturated at W_SAFE here) after the first ``k`` rows
        (:mod:`offboard.safety.dcbf.world_rows`); returns the new row count."""
        if self.qp is None or self.lag is None:
            raise RuntimeError("DcbfFilter.configure(vehicle, dt) was not called")
        m = planes.at(p)
        if m == 0:
            return k
        self._world_of = (planes, k, m, p)
        self.qp.fit_rows(k + 2 * m)
        prm = self._params
        plane_rows_into(
            planes.normals, planes.offsets, m, vec3(p), vec3(v), vec3(a0),
            vec3(saturate_norm(w, W_SAFE)), self.lag.table, self.lag.T, prm[P_TAU],
            WORLD_GAMMA, prm[P_GROUND_ERR], prm[P_GROUND_ERR], self._g, self._rhs, k,
        )
        if prm[P_ALT_ERR] > 0.0:  # the same rows for the tight QP
            self._g_alt[k : k + 2 * m] = self._g[k : k + 2 * m]
            self._rhs_alt[k : k + 2 * m] = self._rhs[k : k + 2 * m]
        return k + 2 * m

    def solve_limited(
        self, u_try: np.ndarray, clf: ClfTerms, k: int, h_min: float, w: np.ndarray,
        z2: np.ndarray, held: bool, t0: float, world: bool = False,
    ) -> SafetyOutput:
        """:meth:`solve_rows` with the speed rows of :attr:`speed` (prepared this step;
        :mod:`offboard.safety.dcbf.speed_rows`) after the first ``k`` rows. ``held``:
        ``u_try`` keeps the pair and ground rows and the input set; it is flown when no
        world rows were added (``world``) and it keeps the speed limit too (``t0``: the
        step's clock start, for ``solve_us``). A first cut goes in
        when ``u_try`` is near the limit; while the answer is outside it, one more cut (at
        most MAX_CUTS), then the inner cube. If the QP needs its slack (or fails) with speed
        rows, it is solved again without them: the pair, ground and world rows come first
        (their claim needs σ = 0). Where they alone need none, the command flown is the one
        nearest the limit's braking command that keeps them (:meth:`_recover`): the limit
        gives way only as far as they need. Where they need slack too, their answer is
        flown unless it needs as much (to SLACK_TOL) as the one with the speed rows: then
        the pair rows are relaxed either way, and the speed rows stay."""
        lim = self.speed
        if lim is None or self.qp is None:
            raise RuntimeError("DcbfFilter.solve_limited: no max_transient_speed_mps")
        if held and not world and lim.excess(u_try) <= 0.0:
            return SafetyOutput(u_try, h_min, QPStatus.INACTIVE, (time.perf_counter() - t0) * 1e6)
        cuts = [lim.direction(u_try)] if lim.near(u_try) else []
        cube = False
        base: SafetyOutput | None = None  # the answer without speed rows, if needed
        while True:
            n = lim.write(cuts, cube, self._g, self._rhs, k)
            self.qp.fit_rows(k + n)
            if n and self._params[P_ALT_ERR] > 0.0:  # the same rows for the tight QP
                self._g_alt[k : k + n] = self._g[k : k + n]
                self._rhs_alt[k : k + n] = self._rhs[k : k + n]
            self._speed_from = k if n else -1
            res = self.solve_rows(u_try, clf, k + n, h_min, w, z2, unheld=not held)
            if res.qp_status.degraded and n:  # σ > 0 (or failed) with them: without them?
                if base is None:
                    base = self.solve_rows(u_try, clf, k, h_min, w, z2, unheld=not held)
                if not base.qp_status.degraded:  # the barrier rows alone hold: brake
                    self._speed_from = -1
                    return self._recover(clf, k, h_min, w, z2, base)
                if (res.qp_status is not QPStatus.RELAXED
                        or res.violation > base.violation + SLACK_TOL):
                    self._speed_from = -1  # they cost the other rows slack: dropped
                    return base
            if cube or lim.excess(res.u) <= TOL:
                return res
            if len(cuts) < MAX_CUTS:
                cuts.append(lim.direction(res.u))
            else:
                cube = True

    def _recover(self, clf: ClfTerms, k: int, h_min: float, w: np.ndarray, z2: np.ndarray,
                 base: SafetyOutput) -> SafetyOutput:
        """The speed limit and the first ``k`` rows cannot hold together, and those rows alone
        can (``base``, their answer for the nominal command): the command nearest the speed
        limit's braking command ``u_b`` that keeps them (no CLF row; σ = 0 to the exact
        penalty), so the follower exceeds v_t only as far as its barrier rows make it.
        ``base`` if that needs slack after all."""
        lim = self.speed
        if lim is None:
            raise RuntimeError("DcbfFilter._recover: no max_transient_speed_mps")
        res = self.solve_rows(lim.u_b, ClfTerms(0.0, 0.0, NO_CLF, lim.u_b), k, h_min, w, z2)
        return base if res.qp_status.degraded else res

    def solve_rows(
        self, u_try: np.ndarray, clf: ClfTerms, k: int, h_min: float, w: np.ndarray,
        z2: np.ndarray, unheld: bool = False,
    ) -> SafetyOutput:
        """The QP over the K rows in the buffers, from ``u_try`` = u_nom + sidestep (m/s²);
        its fallback brakes on ``−w − gain·z2`` (w the saturated disturbance estimate,
        z2 the velocity estimate). ``unheld``: :meth:`DcbfQP.solve`'s.

        With a trust region whose tight rows were made this step (:meth:`prepare_trust`),
        the tight QP is solved first, and its answer flown when it needs no slack (σ = 0,
        so the jump bound that its margin assumes holds); else the full QP's, as without
        a trust region."""
        if self.qp is None:
            raise RuntimeError("DcbfFilter.configure(vehicle, dt) was not called")
        gain = self.brake_gain
        res = None
        if self.tight_qp is not None:
            if self._params[P_ALT_ERR] > 0.0:
                res = self.tight_qp.solve(u_try, clf, self._g_alt[:k], self._rhs_alt[:k],
                                          h_min, lambda: -w - gain * z2)
                if res.status in (QPStatus.INACTIVE, QPStatus.SOLVED):
                    self.trust_counts[0] += 1
                else:
                    self.trust_counts[1] += 1
                    res = None
            else:
                self.trust_counts[2] += 1
        if res is None:
            res = self.qp.solve(u_try, clf, self._g[:k], self._rhs[:k], h_min,
                                lambda: -w - gain * z2, unheld)  # the fallback, formed if taken
        return SafetyOutput(
            res.u, res.h_min, res.status, res.solve_us, res.slack, res.violation, res.fallback,
            active_rows(res, self._rows_of, self._world_of, self._speed_from),
        )

    def rows_state(self) -> RowsState:
        """The parameters, lag tables and per-pair state of :func:`dcbf_filter_rows_into`,
        updated in place (the arrays themselves never change after :meth:`configure`)."""
        if self.lag is None:
            raise RuntimeError("DcbfFilter.configure(vehicle, dt) was not called")
        return RowsState(self._params, self.lag.table, self.lag.sens3, self._prev_dv,
                         self._prev_ok, self._rel_acc, self._rel_ok)

    def rows_out(self) -> RowsOut:
        """The row buffers and the sidestep of :func:`dcbf_filter_rows_into` (rewritten
        each step; the QP reads them within the step)."""
        return RowsOut(self._g, self._rhs, self._side, self._g_alt, self._rhs_alt)
