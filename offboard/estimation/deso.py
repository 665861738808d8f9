"""Parameter-adaptive distributed extended state observer, DESO (paper §3; Departures 5–8).

Follower i estimates its position z1, velocity z2 and lumped residual z3 (the extended
state x3: external disturbance and whatever the adaptive model does not explain)::

    ż1 = z2                      − β1 e1
    ż2 = z3 + Φ(z1, z2) ζ̂ + u    − β2 e1 − κ2 e2  (stable sign, Departure 5)
    ż3 =                         − β3 e1 − κ3 e2
    ζ̂̇  = −μ Φᵀ e2 / (1 + ‖Φ‖²) − μ σ ζ̂, ζ̂ in a box  (sign as Departure 5; Departure 8)

with the innovations of Departure 6 (``r_ij = p_j − p_i`` measured as ``g_ij d_ij``)::

    e1 = Σ_j P*_ij [(z1 − ẑ_j1) + r_ij]      e2 = Σ_j P*_ij [(z2 − ẑ_j2) + ṙ_ij]

where ẑ_j is neighbour j's communicated estimate (a leader's broadcast state). κ2 = κ3 = 0
is the paper's observer (e2 only drives ζ̂); κ > 0 (``observer.velocity_gain``) also feeds
the measured relative velocity back into the velocity and extended states.
Rewriting ``e1 = D z1 − b1(τ)``, ``D = Σ_j P*_ij`` and ``b1 = Σ_j P*_ij (ẑ_j1 − r_ij)``, the
data enter through b1 only. Over one control period [t_k, t_k+1] b1 is a first-order hold
``b1(τ) = b1 + τ ḃ1`` (neighbours' estimates extrapolated with their ẑ_j2, the relative
position with the measured relative velocity). The linear part is integrated exactly
(matrix exponential); the input u is resolved at ``substeps`` sub-steps (the realised
virtual control predicted by the inner-loop model, a first-order hold of the command),
Φ(z1,z2)ζ̂ is held over the period and ζ̂ is advanced once per period (μ is small).
The adaptive law is made harmless (docs/estimation.md): Φ is evaluated at a speed saturated
to V_EVAL_MAX, the gradient is normalised, ζ̂ is projected onto a box of physical values,
‖f̂‖ is saturated to F_HAT_MAX, and ζ̂ moves only once the innovations have stayed small
for GATE_HOLD_S (never during start-up transients or outages).
The whole period is then one affine map ``X⁺ = A_S X + Σ_s G_s (u_s + f̂)``.

:func:`offboard.estimation.deso_gains.gain_report` checks the gains per eigen-channel and the
sampled network loop (Departure 7).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from offboard.estimation.bearing import Formation, check_observable
from offboard.estimation.deso_adaptive import (  # noqa: F401 (re-exported)
    F_HAT_MAX,
    V_EVAL_MAX,
    ZETA_BOUND,
    ZETA_HI,
    ZETA_LO,
    adapt_step,
    model_accel,
    regressor_t_times,
)
from offboard.estimation.deso_kernel import (  # noqa: F401 (GATE_* re-exported)
    GATE_E1,
    GATE_E2,
    GATE_HOLD_S,
    MASK_NEIGHBOURS,
    OUT_CONVERGED,
    OUT_E1,
    OUT_E2,
    OUT_LEN,
    OUT_Z1,
    OUT_Z2,
    OUT_Z3,
    OUT_ZETA,
    coast_kernel,
    deso_step_kernel,
    lumped_into,
    model_accel_kernel,
    used_mask,
)
from swarm_common.fastnp import bools, f64
from swarm_common.jit import CallSite
from swarm_common.unmodeled import N_ZETA, regressor  # noqa: F401 (re-exported)


def observer_weights(form: Formation, i: int, leader_anchor: float = 0.0) -> dict[int, np.ndarray]:
    """Innovation weights W_ij of follower i: P*_ij for bearing-graph neighbours (§3), plus
    ``leader_anchor``·I₃ for every leader follower i senses in the desired formation
    (``form.anchor_leaders(i)``: graph neighbours and leaders within the sensing range;
    docs/graphs.md). An option (D21), 0 = the paper's observer: the leader's broadcast
    position and the sensed relative position anchor the estimate directly, adding
    leader_anchor·m_i to follower i's diagonal block of the observer's L_ff (m_i sensed
    leaders). Data of any other leader is ignored (it is not in the weights); a follower
    that senses no leader relies on the bearing innovations only."""
    w: dict[int, np.ndarray] = {j: form.p_star[i, j].copy() for j in form.neighbours[i]}
    if leader_anchor > 0.0:
        for j in form.anchor_leaders(i):
            w[j] = w.get(j, np.zeros((3, 3))) + leader_anchor * np.eye(3)
    return w


def _cont_matrix(
    dmat: np.ndarray, beta: tuple[float, ...], kappa: tuple[float, ...] = (0.0, 0.0)
) -> np.ndarray:
    """Continuous 18×18 matrix of X = [z1, z2, z3, b1, ḃ1, w] (w = Φζ̂ + u held).

    ``e1 = D z1 − b1(τ)``; the velocity innovation is ``e2 = D z2 − ḃ1`` (ḃ1 = Σ W(ẑ_j2 −
    ṙ_ij) is both the slope of b1 and the velocity datum), entering ż2, ż3 with κ2, κ3.
    """
    b1, b2, b3 = beta
    k2, k3 = kappa
    a = np.zeros((18, 18))
    i3 = np.eye(3)
    a[0:3, 0:3] = -b1 * dmat
    a[0:3, 3:6] = i3
    a[0:3, 9:12] = b1 * i3
    a[3:6, 0:3] = -b2 * dmat
    a[3:6, 6:9] = i3
    a[3:6, 9:12] = b2 * i3
    a[3:6, 15:18] = i3
    a[6:9, 0:3] = -b3 * dmat
    a[6:9, 9:12] = b3 * i3
    a[9:12, 12:15] = i3
    if k2 or k3:
        a[3:6, 3:6] = -k2 * dmat
        a[3:6, 12:15] = k2 * i3
        a[6:9, 3:6] = -k3 * dmat
        a[6:9, 12:15] = k3 * i3
    return a


class DESO:
    """Observer of follower ``index``; state z1, z2, z3 (3,) and ζ̂ (6,).

    The per-period arithmetic is compiled (:mod:`offboard.estimation.deso_kernel`); the class keeps
    the state, the neighbour bookkeeping and the matrices of each neighbour set (numpy,
    cached). Each period replaces z1, z2, z3 (and ζ̂ when it adapts) by new arrays, and
    nothing writes them in place: a follower publishes them as they are
    (:meth:`offboard.agent.follower.FollowerAgent._estimate`).
    """

    def __init__(
        self,
        form: Formation,
        index: int,
        beta: tuple[float, ...],
        mu: float,
        sigma: float,
        substeps: int,
        dt: float,
        ground_effect_height: float,
        z1: np.ndarray,
        z2: np.ndarray,
        leader_anchor: float = 0.0,
        kappa: tuple[float, ...] = (0.0, 0.0),
    ) -> None:
        self.form = form
        check_observable(form, leader_anchor)  # L_ff + anchors positive definite
        self.weights = observer_weights(form, index, leader_anchor)
        self.kappa = (float(kappa[0]), float(kappa[1]))
        self.index = index
        self.beta = tuple(float(b) for b in beta)
        self.mu = float(mu)
        self.sigma = float(sigma)
        self.substeps = int(substeps)
        self.dt = float(dt)
        self.delta = self.dt / self.substeps
        self.h = float(ground_effect_height)
        self.nbrs = sorted(self.weights)
        # the neighbour set of an update as a bit mask (used_mask), and each mask's set
        self._nbr_idx = np.array(self.nbrs, dtype=np.int64)
        self._mask = CallSite(used_mask) if len(self.nbrs) <= MASK_NEIGHBOURS else None
        self._used_of: dict[int, tuple[int, ...]] = {}
        self.z1 = np.array(z1, dtype=float)
        self.z2 = np.array(z2, dtype=float)
        self.z3 = np.zeros(3)
        self.zeta = np.zeros(N_ZETA)
        self._cache: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._pu_cache: dict[tuple[int, ...], np.ndarray] = {}
        # per neighbour set: (A_S, G, D, W (k,3,3), indices (k,) int64), for the kernel
        self._step_cache: dict[
            tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
        ] = {}
        self.last_e1 = np.zeros(3)
        self.last_e2 = np.zeros(3)
        self.n_used = 0
        self._f_hat: np.ndarray | None = None  # f̂ at the current state (set by lumped())
        self._step = CallSite(deso_step_kernel)  # its arguments' types are fixed
        self.converged_s = 0.0  # s for which the innovations have stayed inside the gate

    def _matrices(self, used: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_S (15×15), G (15×3S), D) for this neighbour set (cached)."""
        m = self._cache.get(used)
        if m is None:
            dmat = np.zeros((3, 3))
            for j in used:
                dmat += self.weights[j]
            full = expm(_cont_matrix(dmat, self.beta, self.kappa) * self.delta)
            mx, mw = full[:15, :15], full[:15, 15:18]
            s_ = self.substeps
            a_s = np.linalg.matrix_power(mx, s_)
            g = np.hstack([np.linalg.matrix_power(mx, s_ - 1 - k) @ mw for k in range(s_)])
            m = (a_s, g, dmat)
            self._cache[used] = m
        return m

    def _used(self, valid: np.ndarray, have: np.ndarray) -> tuple[int, ...]:
        """The neighbours with a valid measurement (``valid`` (N,)) and a usable estimate
        (``have`` (N,)), in order: one compiled pass to a bit mask, its set cached (a tuple
        built in Python read two numpy scalars per neighbour)."""
        if self._mask is None:
            return tuple([j for j in self.nbrs if valid[j] and have[j]])
        m = self._mask.call(self._nbr_idx, bools(valid), bools(have))
        used = self._used_of.get(m)
        if used is None:
            used = tuple(j for r, j in enumerate(self.nbrs) if m >> r & 1)
            self._used_of[m] = used
        return used

    def _stacked_weights(self, used: tuple[int, ...]) -> np.ndarray:
        """(k,3,3) W_ij of the neighbours ``used``, in that order (cached per set)."""
        pu = self._pu_cache.get(used)
        if pu is None:
            pu = np.array([self.weights[j] for j in used])
            self._pu_cache[used] = pu
        return pu

    def _step_arrays(
        self, used: tuple[int, ...]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A_S, G, D, W (k,3,3), indices (k,)) of this neighbour set as contiguous arrays
        for :func:`~offboard.estimation.deso_kernel.deso_step_kernel` (cached per set)."""
        arrs = self._step_cache.get(used)
        if arrs is None:
            a_s, g, dmat = self._matrices(used)
            c = np.ascontiguousarray
            arrs = (c(a_s, dtype=np.float64), c(g, dtype=np.float64),
                    c(dmat, dtype=np.float64), c(self._stacked_weights(used), dtype=np.float64),
                    np.array(used, dtype=np.int64))
            self._step_cache[used] = arrs
        return arrs

    def lumped(self) -> np.ndarray:
        """Estimate of the lumped disturbance acceleration Φζ + d/m: f̂ + z3 (one compiled
        call, :func:`offboard.estimation.deso_kernel.lumped_into`; f̂ is kept for :meth:`update`)."""
        out = np.empty((2, 3))  # a new array from Python: cheaper than two the kernel boxes
        lumped_into(self.z1, self.z2, self.zeta, self.h, self.z3, out)
        return self.adopt_lumped(out)

    def adopt_lumped(self, out: np.ndarray) -> np.ndarray:
        """Keep f̂ of ``out`` (2,3) [f̂, z3 + f̂], :func:`lumped_into` of the current
        state (made here or by :func:`offboard.safety.dcbf.front.dcbf_front_into`), for
        :meth:`update`; returns z3 + f̂ (m/s²)."""
        self._f_hat = out[0]
        return out[1]

    def coast(self, u_sub: np.ndarray) -> None:
        """Dead-reckon one control period with the model (z3 and ζ held): a period
        with no relative information, or one the daemon missed (u_sub: (substeps, 3),
        m/s²)."""
        self._f_hat = None
        u = f64(u_sub)
        self.z1, self.z2 = coast_kernel(self.z1, self.z2, self.z3, self.zeta,
                                        u[: self.substeps], self.h, self.delta)

    def update(
        self,
        rel_pos: np.ndarray,
        rel_vel: np.ndarray,
        valid: np.ndarray,
        peer_rows: np.ndarray,
        have: np.ndarray,
        u_sub: np.ndarray,
    ) -> None:
        """Integrate from t_k to t_k+1.

        rel_pos/rel_vel (N,3): measured p_j − p_i, v_j − v_i at t_k; valid (N,) mask;
        peer_rows (N,≥6): neighbours' estimates (leaders' states) for t_k by scenario
        index, ẑ_j1 then ẑ_j2 (:mod:`offboard.estimation.peer_table`), usable where ``have`` (N,);
        u_sub (substeps, 3): applied virtual control per sub-step.
        """
        f_cached, self._f_hat = self._f_hat, None
        used = self._used(valid, have)
        self.n_used = len(used)
        if not used:  # no relative information: dead-reckon with the model
            self.converged_s = 0.0
            self.coast(u_sub)
            return
        a_s, g, dmat, pu, idx = self._step_arrays(used)
        f_hat = (f_cached if f_cached is not None
                 else model_accel_kernel(self.z1, self.z2, self.zeta, self.h))
        out = np.empty(OUT_LEN)  # a new array from Python: cheaper than one the kernel boxes
        self._step.call(
            a_s, g, dmat, pu, idx, f64(peer_rows), f64(rel_pos), f64(rel_vel), self.z1,
            self.z2, self.z3, self.zeta, f64(u_sub), f_hat, self.h, self.mu, self.sigma,
            self.dt, self.converged_s, out,
        )
        # new arrays each period (views of the kernel's one output array)
        self.z1, self.z2, self.z3 = out[OUT_Z1], out[OUT_Z2], out[OUT_Z3]
        self.last_e1, self.last_e2, self.zeta = out[OUT_E1], out[OUT_E2], out[OUT_ZETA]
        self.converged_s = float(out[OUT_CONVERGED])
