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

:func:`gain_report` checks the gains per eigen-channel (``s³ + β1λ s² + β2λ s + β3λ``
Hurwitz ⇔ β1β2λ > β3) and the *sampled* network loop by the spectral radius of its
one-period transition, with post-update publishing and with a one-step stale exchange.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from offboard.bearing import Formation, check_observable
from offboard.deso_adaptive import (  # noqa: F401 (re-exported)
    F_HAT_MAX,
    V_EVAL_MAX,
    ZETA_BOUND,
    ZETA_HI,
    ZETA_LO,
    adapt_step,
    model_accel,
    regressor_t_times,
)
from offboard.deso_kernel import (  # noqa: F401 (GATE_* re-exported)
    GATE_E1,
    GATE_E2,
    GATE_HOLD_S,
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
)
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


@dataclass
class GainReport:
    """Numbers of the DESO gain check (Departure 7); ``lines()`` for printing at start-up."""

    beta: tuple[float, ...]
    dt: float
    substeps: int
    lambda_ff: np.ndarray
    margin: np.ndarray  # β1 β2 λ − β3 per channel (>0 ⇔ Hurwitz)
    max_real_pole: float  # slowest continuous pole over all channels (<0)
    fastest_bandwidth: float  # β1 λ_max  (rad/s)
    euler_number: float  # δ β1 λ_max with δ = dt/substeps (explicit Euler needs < 2)
    rho_post_update: float  # spectral radius, exact sub-steps, post-update exchange
    rho_stale: float  # same with neighbours' estimates one period stale
    rho_euler_post: float  # explicit Euler sub-steps, post-update exchange
    rho_single_euler_stale: float  # one Euler step per period, one-step stale (naive)
    paper_condition: bool  # β2 > β1 + β3/λ_min (paper §3)
    kappa: tuple[float, ...] = (0.0, 0.0)  # velocity-innovation gains κ2, κ3
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return bool(self.max_real_pole < 0.0 and self.rho_post_update < 1.0)

    def lines(self) -> list[str]:
        b = self.beta
        return [
            f"DESO gains beta = {b[0]:g}/{b[1]:g}/{b[2]:g}, kappa = {self.kappa[0]:g}/"
            f"{self.kappa[1]:g}, dt = {self.dt:g} s x {self.substeps} sub-steps",
            f"  lambda(observer Laplacian) in [{self.lambda_ff[0]:.3f}, {self.lambda_ff[-1]:.3f}]; "
            f"channel margin min(b1 b2 lam - b3) = {self.margin.min():.1f} "
            f"({'Hurwitz' if np.all(self.margin > 0) else 'NOT Hurwitz'} without kappa); "
            f"slowest pole {self.max_real_pole:.3f} 1/s",
            f"  paper condition b2 > b1 + b3/lam_min: {self.paper_condition}",
            f"  fastest channel b1*lam_max = {self.fastest_bandwidth:.1f} rad/s; "
            f"dt_sub*b1*lam_max = {self.euler_number:.2f} (< 2 for explicit Euler)",
            f"  sampled loop spectral radius: exact sub-steps post-update "
            f"{self.rho_post_update:.4f}, "
            f"one-step stale {self.rho_stale:.4f}; Euler sub-steps {self.rho_euler_post:.4f}; "
            f"single Euler step + stale {self.rho_single_euler_stale:.4f}",
            f"  => {'OK' if self.ok else 'UNSTABLE'}",
        ]


def _network_transition(
    form: Formation, beta: tuple[float, ...], dt: float, substeps: int, euler: bool,
    leader_anchor: float = 0.0, kappa: tuple[float, ...] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """One-period error transition of all followers: E_{k+1} = T0 E_k + T1 E_nbr.

    E = [z̃1; z̃2; z̃3] stacked per follower (9 per follower). T1 multiplies the neighbour
    data actually used (current for post-update, previous for stale).
    """
    fol = form.follower_idx
    nf = len(fol)
    pos = {a: k for k, a in enumerate(fol)}
    t0 = np.zeros((9 * nf, 9 * nf))
    t1 = np.zeros((9 * nf, 9 * nf))
    delta = dt / substeps
    for k, i in enumerate(fol):
        wts = observer_weights(form, i, leader_anchor)
        dmat = np.zeros((3, 3))
        for pij in wts.values():
            dmat += pij
        a = _cont_matrix(dmat, beta, kappa)
        m = np.eye(18) + a * delta if euler else expm(a * delta)
        mm = np.linalg.matrix_power(m, substeps)[:9, :15]
        t0[9 * k : 9 * k + 9, 9 * k : 9 * k + 9] = mm[:, :9]
        for j, pij in wts.items():
            if j not in pos:
                continue
            c = pos[j]
            t1[9 * k : 9 * k + 9, 9 * c : 9 * c + 3] += mm[:, 9:12] @ pij
            t1[9 * k : 9 * k + 9, 9 * c + 3 : 9 * c + 6] += mm[:, 12:15] @ pij
    return t0, t1


def _rho(t0: np.ndarray, t1: np.ndarray, stale: bool) -> float:
    if not stale:
        return float(np.max(np.abs(np.linalg.eigvals(t0 + t1))))
    n = t0.shape[0]
    big = np.block([[t0, t1], [np.eye(n), np.zeros((n, n))]])
    return float(np.max(np.abs(np.linalg.eigvals(big))))


def gain_report(
    form: Formation, beta: tuple[float, ...], dt: float, substeps: int,
    leader_anchor: float = 0.0, kappa: tuple[float, ...] = (0.0, 0.0),
) -> GainReport:
    """Per-channel and sampled-loop stability numbers of the DESO gains (Departure 7).

    The channels are the eigenvalues of the observer's Laplacian
    ``L_ff + leader_anchor·blockdiag(m_i I₃)`` (m_i leaders sensed by follower i;
    ``Formation.observer_laplacian``; = L_ff for the paper's observer).
    """
    b1, b2, b3 = (float(x) for x in beta)
    lam = form.observer_eigs(leader_anchor)
    margin = b1 * b2 * lam - b3
    k2, k3 = (float(k) for k in kappa)
    poles = [
        np.linalg.eigvals(np.array([[-b1 * x, 1.0, 0.0], [-b2 * x, -k2 * x, 1.0],
                                    [-b3 * x, -k3 * x, 0.0]]))
        for x in lam
    ]
    max_re = float(max(np.max(p.real) for p in poles))
    la = leader_anchor
    t0, t1 = _network_transition(form, (b1, b2, b3), dt, substeps, euler=False, leader_anchor=la,
                                 kappa=(k2, k3))
    rho_post = _rho(t0, t1, stale=False)
    rho_stale = _rho(t0, t1, stale=True)
    e0, e1 = _network_transition(form, (b1, b2, b3), dt, substeps, euler=True, leader_anchor=la,
                                 kappa=(k2, k3))
    rho_e = _rho(e0, e1, stale=False)
    s0, s1 = _network_transition(form, (b1, b2, b3), dt, 1, euler=True, leader_anchor=la,
                                 kappa=(k2, k3))
    rho_s = _rho(s0, s1, stale=True)
    return GainReport(
        beta=(b1, b2, b3),
        dt=dt,
        substeps=substeps,
        lambda_ff=lam,
        margin=margin,
        max_real_pole=max_re,
        fastest_bandwidth=b1 * float(lam[-1]),
        euler_number=dt / substeps * b1 * float(lam[-1]),
        rho_post_update=rho_post,
        rho_stale=rho_stale,
        rho_euler_post=rho_e,
        rho_single_euler_stale=rho_s,
        paper_condition=bool(b2 > b1 + b3 / float(lam[0])),
        kappa=(k2, k3),
    )


class DESO:
    """Observer of follower ``index``; state z1, z2, z3 (3,) and ζ̂ (6,).

    The per-period arithmetic is compiled (:mod:`offboard.deso_kernel`); the class keeps
    the state, the neighbour bookkeeping and the matrices of each neighbour set (numpy,
    cached). Each period replaces z1, z2, z3 (and ζ̂ when it adapts) by new arrays.
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
        for :func:`~offboard.deso_kernel.deso_step_kernel` (cached per set)."""
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
        call, :func:`offboard.deso_kernel.lumped_into`; f̂ is kept for :meth:`update`)."""
        out = np.empty((2, 3))  # a new array from Python: cheaper than two the kernel boxes
        lumped_into(self.z1, self.z2, self.zeta, self.h, self.z3, out)
        return self.adopt_lumped(out)

    def adopt_lumped(self, out: np.ndarray) -> np.ndarray:
        """Keep f̂ of ``out`` (2,3) [f̂, z3 + f̂], :func:`lumped_into` of the current
        state (made here or by :func:`offboard.dcbf_front.dcbf_front_into`), for
        :meth:`update`; returns z3 + f̂ (m/s²)."""
        self._f_hat = out[0]
        return out[1]

    def coast(self, u_sub: np.ndarray) -> None:
        """Dead-reckon one control period with the model (z3 and ζ held): a period
        with no relative information, or one the daemon missed (u_sub: (substeps, 3),
        m/s²)."""
        self._f_hat = None
        u = np.ascontiguousarray(u_sub, dtype=np.float64)
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
        index, ẑ_j1 then ẑ_j2 (:mod:`offboard.peer_table`), usable where ``have`` (N,);
        u_sub (substeps, 3): applied virtual control per sub-step.
        """
        f_cached, self._f_hat = self._f_hat, None
        used = tuple([j for j in self.nbrs if valid[j] and have[j]])
        self.n_used = len(used)
        if not used:  # no relative information: dead-reckon with the model
            self.converged_s = 0.0
            self.coast(u_sub)
            return
        a_s, g, dmat, pu, idx = self._step_arrays(used)
        f_hat = (f_cached if f_cached is not None
                 else model_accel_kernel(self.z1, self.z2, self.zeta, self.h))
        c = np.ascontiguousarray
        out = np.empty(OUT_LEN)  # a new array from Python: cheaper than one the kernel boxes
        deso_step_kernel(
            a_s, g, dmat, pu, idx, c(peer_rows, dtype=np.float64), c(rel_pos, dtype=np.float64),
            c(rel_vel, dtype=np.float64), self.z1, self.z2, self.z3, self.zeta,
            c(u_sub, dtype=np.float64), f_hat, self.h, self.mu, self.sigma, self.dt,
            self.converged_s, out,
        )
        # new arrays each period (views of the kernel's one output array)
        self.z1, self.z2, self.z3 = out[OUT_Z1], out[OUT_Z2], out[OUT_Z3]
        self.last_e1, self.last_e2, self.zeta = out[OUT_E1], out[OUT_E2], out[OUT_ZETA]
        self.converged_s = float(out[OUT_CONVERGED])
