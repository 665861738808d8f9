"""Leader trajectory and the desired-state observer (paper §4.1; Departures 4, 9).

Leader trajectory (Departure 4): every leader moves by the same smooth offset
``p_L(t) = p_L(0) + A (1 − cos ωt)``, ω = 2π f (``[leader_trajectory]``), so the
bearings between leaders stay constant and the desired formation is a rigid translation.

Exosystem (Departure 9): per axis ``x'''' = −ω² x''`` i.e. ``ξ̇ = (S ⊗ I₃) ξ`` with
``ξ = [p, ṗ, p̈, p⃛]`` (12,) and ``S = [[0,1,0,0],[0,0,1,0],[0,0,0,1],[0,0,−ω²,0]]``;
it generates constant + ramp + sinusoid, hence the trajectory above exactly.

Desired-state observer of follower i (§4.1, coupling over bearing-graph neighbours,
leaders' states as known inputs)::

    ξ̂̇_i = (S⊗I₃) ξ̂_i − L Σ_j (I₄⊗P*_ij)(ξ̂_i − ξ̂_j)

Per eigen-channel λ of L_ff the error matrix is S − Lλ I (S commutes with I), so every
channel decays at rate Lλ ≥ L λ_min.

Only bearing-graph neighbours enter (``form.neighbours``; the leaders' ξ only where a leader
is a neighbour), so the observer works on any graph that passes the rigidity check
(λ_min(L_ff) > 0, docs/graphs.md): on a sparse graph the leaders' motion reaches a follower
over several hops and the slowest channel, L λ_min, is what :attr:`rate` reports. Data
handed in for a non-neighbour is ignored. Over one period the neighbours' ξ̂_j are propagated
by the exosystem; with ``c = Σ_j (I₄⊗P*_ij) ξ̂_j`` (ċ = (S⊗I₃) c) the pair (ξ̂_i, c) is
linear time-invariant and is advanced exactly by one 24×24 matrix exponential.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from offboard.estimation.bearing import Formation
from offboard.estimation.peer_table import XI_COL
from offboard.estimation.yaw_turn import turn_by_kernel, turn_coeffs_kernel
from swarm_common.fastnp import f64
from swarm_common.jit import CallSite, kernel

XI_DIM = 12  # ξ = [p*, v*, a*, j*], each (3,) ENU


def xi_p(xi: np.ndarray) -> np.ndarray:
    """Desired position p* (m) of a 12-vector ξ (a view)."""
    return xi[0:3]


def xi_v(xi: np.ndarray) -> np.ndarray:
    """Desired velocity v* (m/s) of ξ (a view)."""
    return xi[3:6]


def xi_a(xi: np.ndarray) -> np.ndarray:
    """Desired acceleration a* (m/s²) of ξ (a view)."""
    return xi[6:9]


def xi_j(xi: np.ndarray) -> np.ndarray:
    """Desired jerk j* (m/s³) of ξ (a view)."""
    return xi[9:12]


def xi_at_rest(p: np.ndarray) -> np.ndarray:
    """ξ = [p, 0, 0, 0]: standing still at ``p`` (a new array)."""
    return np.concatenate([np.asarray(p, dtype=float), np.zeros(XI_DIM - 3)])


def exo_matrix(omega: float) -> np.ndarray:
    """4×4 exosystem matrix S of x'''' = −ω² x'' (Departure 9)."""
    s = np.zeros((4, 4))
    s[0, 1] = s[1, 2] = s[2, 3] = 1.0
    s[3, 2] = -omega * omega
    return s


class LeaderTrajectory:
    """p_L(t) = p_L(0) + A(1 − cos ωt) and its derivatives up to order 3."""

    def __init__(self, p0: np.ndarray, amplitude: np.ndarray, frequency_hz: float) -> None:
        self.p0 = np.ascontiguousarray(p0, dtype=float)
        self.amp = np.ascontiguousarray(amplitude, dtype=float)
        self.omega = 2.0 * math.pi * float(frequency_hz)
        self._state = CallSite(leader_state_kernel)  # its arguments' types are fixed

    def state(self, t: float) -> np.ndarray:
        """ξ(t) = [p, ṗ, p̈, p⃛] (12,) (compiled: :func:`leader_state_kernel`)."""
        out = np.empty(12)  # a new array from Python: cheaper than one the kernel boxes
        self._state.call(self.p0, self.amp, self.omega, float(t), out)
        return out


@kernel
def leader_state_kernel(
    p0: np.ndarray, amp: np.ndarray, omega: float, t: float, out: np.ndarray
) -> None:
    """ξ(t) = [p, ṗ, p̈, p⃛] into ``out`` (12,) (the caller's new array: none to box) of
    p(t) = p0 + A(1 − cos ωt), p0 and A (3,) in m, ω in
    rad/s, t in s: ``A ω sin ωt``, ``A ω² cos ωt``, ``−A ω³ sin ωt``, each product taken
    left to right per axis (ω³ as ``ω**3``, the C library's pow)."""
    c, s = math.cos(omega * t), math.sin(omega * t)
    w3 = math.pow(omega, 3.0)
    for i in range(3):
        a = amp[i]
        out[i] = p0[i] + a * (1.0 - c)
        out[3 + i] = a * omega * s
        out[6 + i] = a * omega * omega * c
        out[9 + i] = -a * w3 * s


def exo_propagator(omega: float, dt: float) -> np.ndarray:
    """12×12 exact propagator expm((S⊗I₃) dt) of ξ."""
    return expm(np.kron(exo_matrix(omega), np.eye(3)) * dt)


@kernel
def observer_step(
    mx: np.ndarray, mc: np.ndarray, pu: np.ndarray, idx: np.ndarray, peer_rows: np.ndarray,
    xi: np.ndarray, out: np.ndarray,
) -> None:
    """One period of the desired-state observer (§4.1), compiled:
    ``ξ̂⁺ = M_x ξ̂ + M_c c`` with ``c = Σ_j (I₄ ⊗ P*_ij) ξ̂_j``, written into ``out`` (12,)
    (the caller's new array, not ``xi``: none to box). :func:`observer_core` with the
    neighbours read as they are (its ``yaw`` unread: ``xi`` stands in, no array to make)."""
    observer_core(mx, mc, pu, idx, peer_rows, xi, xi, False, out)


@kernel
def observer_core(
    mx: np.ndarray, mc: np.ndarray, pu: np.ndarray, idx: np.ndarray, peer_rows: np.ndarray,
    xi: np.ndarray, yaw: np.ndarray, turn: bool, out: np.ndarray,
) -> None:
    """:func:`observer_step`, each neighbour's ξ̂_j turned by −ψ (the jet ``yaw`` (4,),
    :func:`~offboard.estimation.yaw_turn.turn_by_kernel`) as it is read when ``turn``: the
    step of a yawing formation's observer in its frame
    (:mod:`offboard.estimation.formation_frame`).

    mx, mc (12,12) the exact one-period maps of :meth:`DesiredStateObserver._matrices`;
    pu (k,3,3) the P*_ij of the k neighbours used and idx (k,) their scenario indices
    (int64); peer_rows (N,21) the agents' rows by scenario index, ξ̂_j (m, m/s, m/s², m/s³)
    in columns 9–20 (:mod:`offboard.estimation.peer_table`); xi (12,) own ξ̂. Sums run left to
    right over neighbours, then components."""
    if peer_rows.shape[1] < XI_COL + 12 or out.shape[0] != 12:
        raise ValueError("observer_step: rows too short or out not (12,)")
    for n in range(idx.shape[0]):
        if not 0 <= idx[n] < peer_rows.shape[0]:
            raise ValueError("observer_step: a neighbour index outside the rows")
    c = np.zeros(12)
    seg = np.empty(12)
    e = np.empty(4, dtype=np.complex128)
    if turn:
        turn_coeffs_kernel(yaw, -1.0, e)
    for n in range(pu.shape[0]):
        row = idx[n]
        for q in range(12):
            seg[q] = peer_rows[row, XI_COL + q]
        if turn:
            turn_by_kernel(seg, e, seg)
        for d in range(4):
            for i in range(3):
                acc = 0.0
                for j in range(3):
                    acc += pu[n, i, j] * seg[3 * d + j]
                c[3 * d + i] += acc
    for r in range(12):
        acc = 0.0
        for q in range(12):
            acc += mx[r, q] * xi[q]
        acc2 = 0.0
        for q in range(12):
            acc2 += mc[r, q] * c[q]
        out[r] = acc + acc2


class DesiredStateObserver:
    """Estimate ξ̂_i of follower ``index``'s desired state (§4.1)."""

    def __init__(
        self,
        form: Formation,
        index: int,
        omega: float,
        gain: float,
        dt: float,
        xi0: np.ndarray,
    ) -> None:
        self.form = form
        self.index = index
        self.omega = float(omega)
        self.gain = float(gain)
        self.dt = float(dt)
        self.nbrs = list(form.neighbours[index])
        self._nbr_idx = np.array(self.nbrs, dtype=np.int64)  # read by :meth:`maps`
        self.xi = np.array(xi0, dtype=float)
        self.exo = exo_propagator(self.omega, self.dt)
        self._step = CallSite(observer_step)  # its arguments' types are fixed
        # :meth:`maps`' last ``have`` over the neighbours, and its maps
        self._have_key: bytes | None = None
        self._have_maps: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._cache: dict[
            tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
        ] = {}

    def _matrices(
        self, used: tuple[int, ...]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(M_x (12×12), M_c (12×12), the stacked (k,3,3) P*_ij, the indices (k,) int64)
        for this neighbour set (cached: computed once per set)."""
        m = self._cache.get(used)
        if m is None:
            dmat = np.zeros((3, 3))
            for j in used:
                dmat += self.form.p_star[self.index, j]
            sk = np.kron(exo_matrix(self.omega), np.eye(3))
            a = np.zeros((24, 24))
            a[:12, :12] = sk - self.gain * np.kron(np.eye(4), dmat)
            a[:12, 12:] = self.gain * np.eye(12)
            a[12:, 12:] = sk
            full = expm(a * self.dt)
            pu = self.form.projectors(self.index, used)  # (k,3,3), symmetric
            m = (full[:12, :12].copy(), full[:12, 12:].copy(), np.ascontiguousarray(pu),
                 np.array(used, dtype=np.int64))
            self._cache[used] = m
        return m

    def maps(
        self, have: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The one-period maps of :meth:`_matrices` for the neighbours that ``have`` (N,)
        marks usable, or None when there is none (the estimate then runs open loop on the
        exosystem). Only the neighbours' entries are read: the cost follows the
        neighbours, not N."""
        key = np.asarray(have, dtype=bool)[self._nbr_idx].tobytes()
        if key != self._have_key:  # the last set is kept: it rarely changes between steps
            used = tuple([j for j in self.nbrs if have[j]])
            self._have_maps = self._matrices(used) if used else None
            self._have_key = key
        return self._have_maps

    def update(self, peer_rows: np.ndarray, have: np.ndarray) -> None:
        """Advance ξ̂ from t_k to t_k+1 given neighbours' ξ̂_j (leaders' ξ) for t_k: the
        rows (N,21) of :mod:`offboard.estimation.peer_table` by scenario index, usable where
        ``have`` (N,)."""
        maps = self.maps(have)
        if maps is None:
            self.xi = self.exo @ self.xi
            return
        mx, mc, pu, idx = maps
        out = np.empty(12)  # a new array from Python: cheaper than one the kernel boxes
        self._step.call(mx, mc, pu, idx, f64(peer_rows), self.xi, out)
        self.xi = out

    @property
    def rate(self) -> float:
        """Slowest decay rate L λ_min(L_ff) of the network's estimate error (1/s)."""
        return self.gain * self.form.lambda_min

    @property
    def p(self) -> np.ndarray:
        """p̂* (m)."""
        return xi_p(self.xi)

    @property
    def v(self) -> np.ndarray:
        """v̂* (m/s)."""
        return xi_v(self.xi)

    @property
    def a(self) -> np.ndarray:
        """â* (m/s²)."""
        return xi_a(self.xi)

    @property
    def j(self) -> np.ndarray:
        """ĵ* (m/s³)."""
        return xi_j(self.xi)
