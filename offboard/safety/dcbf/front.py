"""The dcbf follower's step from its state to the QP in one compiled call (issue 11).

Between its measurements and the QP solver a dcbf follower's step (``Method.DCBF``,
:meth:`offboard.agent.follower.FollowerAgent.step`) is one compiled call,
:func:`dcbf_front_into`, the only path of the dcbf filter from the follower's state to
its QP. It chains these kernels:

1. the lumped-disturbance estimate ``[f̂, z3 + f̂]``
   (:func:`offboard.estimation.deso_kernel.lumped_into`);
2. its saturation at ``W_MAX`` for the controller
   (:func:`~offboard.safety.dcbf.kernel.saturate_into`, the same in-order sum as
   :func:`offboard.safety.base.saturate_norm`);
3. the CLF terms and the nominal control (:func:`offboard.safety.clf_kernel.nominal_into`);
4. Δp, Δv of the sensed pairs (:func:`offboard.estimation.sensing_kernel.pair_rows`),
   followed by the rows of the neighbours that are not sensed but predicted into range
   (docs/safety.md §5c; their margins, flagged as predicted);
5. the full-share mask (:func:`offboard.estimation.peer_table.full_share_rows`);
6. the others' accelerations (:func:`offboard.estimation.neighbour_accel.neighbour_accel_rows`);
7. the estimate saturated again at ``W_SAFE`` and the barrier rows
   (:func:`offboard.safety.dcbf.step_kernel.dcbf_filter_rows_into`);
8. the QP's shortcut: whether ``u_nom`` plus the sidestep keeps every row and the input
   set (:func:`offboard.safety.dcbf.kernel.rows_hold_kernel`); in about 70 % of cube8's
   steps it does, and the step needs no solver.

The call's arguments travel in typed groups (``typing.NamedTuple``): :class:`DesoState`,
:class:`Measured`, :class:`Unsensed`, :class:`Silence`, :class:`AccSlots`,
:class:`InnerMotion`, :class:`InputRows`, :class:`FrontOut` here and the rows'
:class:`~offboard.safety.dcbf.step_kernel.RowsState` and
:class:`~offboard.safety.dcbf.step_kernel.RowsOut`. The kernel unpacks each group by
position, and :class:`DcbfFront` (which keeps the call's constant groups and output
buffers per follower) passes them as plain tuples in their fields' order: numba types a
NamedTuple argument from Python on its slow path, which doubled the call's time.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from offboard.estimation.deso import DESO
from offboard.estimation.deso_kernel import lumped_into
from offboard.estimation.neighbour_accel import NeighbourAccel, neighbour_accel_rows
from offboard.estimation.peer_table import full_share_rows
from offboard.estimation.sensing_kernel import pair_rows
from offboard.safety.base import W_SAFE, SafetyOutput
from offboard.safety.clf_kernel import nominal_into
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.kernel import rows_hold_kernel, saturate_into
from offboard.safety.dcbf.step_kernel import (
    GroundInput,
    OwnMotion,
    PairRows,
    RowsOut,
    RowsState,
    dcbf_filter_rows_into,
)
from offboard.safety.rcbf.clf_rcbf import (
    AW_BRAKE_SHARE,
    AW_RESERVE,
    CLF_OUT,
    NO_BOX,
    clf_terms_from,
)
from swarm_common.enums import QPStatus
from swarm_common.fastnp import f64, rows3
from swarm_common.jit import CallSite, kernel
from swarm_common.scenario.model import ControllerConfig

# layout of the scalar parameters of dcbf_front_into (front_params)
F_TAU_FF = 0  # feed-forward look-ahead τ_rp (s)
F_KP, F_KD, F_LAMBDA, F_KS = 1, 2, 3, 4  # the nominal law's gains
F_BRAKE_SHARE, F_RESERVE = 5, 6  # anti-windup constants (offboard.safety.rcbf.clf_rcbf)
F_W_MAX = 7  # the controller's bound on the disturbance estimate (m/s²)
F_W_SAFE = 8  # the filter's bound on it (m/s²)
F_A_MAX = 9  # bound on an other agent's estimated acceleration (m/s²)
F_DESO_H = 10  # the DESO's ground-effect height (m)
N_FRONT = 11


class DesoState(NamedTuple):
    """The DESO's state (:class:`offboard.estimation.deso.DESO`), read only."""

    z1: np.ndarray  # (3,) position estimate (m)
    z2: np.ndarray  # (3,) velocity estimate (m/s)
    zeta: np.ndarray  # (6,) ζ̂
    z3: np.ndarray  # (3,) disturbance state (m/s²)


class Measured(NamedTuple):
    """The sensed pairs of the step."""

    sel: np.ndarray  # (M,) int64 scenario indices
    rel_p: np.ndarray  # (N,3) measured p_j − p_i (m)
    rel_v: np.ndarray  # (N,3) measured v_j − v_i (m/s)


class Unsensed(NamedTuple):
    """The E neighbours predicted into sensing range but not sensed
    (:class:`offboard.agent.unsensed.UnsensedNeighbours`); E may be 0."""

    idx: np.ndarray  # (E,) int64 scenario indices
    dp: np.ndarray  # (E,3) predicted Δp = p_i − p_j (m)
    dv: np.ndarray  # (E,3) predicted Δv (m/s)
    margin: np.ndarray  # (E,) the prediction's error bound (m)


class Silence(NamedTuple):
    """The full-share inputs (:func:`offboard.estimation.peer_table.full_share_rows`)."""

    full: np.ndarray  # (N,) bool: leader, never heard from or not cooperating
    t_tab: np.ndarray  # (N,) each agent's newest stamp (s)
    since: float  # an agent silent since before this (s) ...
    others_heard: bool  # ... stands out when others were heard since


class AccSlots(NamedTuple):
    """The neighbours' two newest velocity estimates (:class:`NeighbourAccel`'s table)."""

    t: np.ndarray  # (2,N) their times (s)
    z2: np.ndarray  # (2,N,3) velocities (m/s)


class InnerMotion(NamedTuple):
    """The inner-loop model's own motion, each (3,) (m/s²)."""

    a_real: np.ndarray  # realised virtual control now
    u_prev: np.ndarray  # the previous command
    a_mean: np.ndarray  # mean realised control over the last period


class InputRows(NamedTuple):
    """The QP's input set rows ``lo ≤ A_U u ≤ hi`` and its row capacity."""

    a_u: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    k_cap: int


class FrontOut(NamedTuple):
    """The caller's output buffers of :func:`dcbf_front_into`."""

    lumped: np.ndarray  # (2,3) [f̂, z3 + f̂]
    w: np.ndarray  # (3,) the estimate saturated at W_MAX
    clf: np.ndarray  # (CLF_OUT,) [V, L_fV, L_gV, u_nom]
    dp: np.ndarray  # (≥ M + E, 3) Δp of the rows, sensed then predicted
    dv: np.ndarray  # (≥ M + E, 3) Δv
    u_try: np.ndarray  # (3,) u_nom + sidestep


@kernel
def dcbf_front_into(
    prm: np.ndarray, deso: DesoState, xi: np.ndarray, meas: Measured, unsensed: Unsensed,
    silence: Silence, acc: AccSlots, inner: InnerMotion, ground: bool, floor: float,
    state: RowsState, rows_out: RowsOut, input_rows: InputRows, out: FrontOut,
) -> tuple[int, float, bool]:
    """Steps 1–8 of the module docstring; returns (K rows, h_min (m²), held).

    ``prm`` (N_FRONT,) the ``F_*`` scalars; ξ (12,) the desired state; ``ground`` adds
    the ground barrier at ``floor`` (m); ``state`` the filter's parameters, lag tables
    and per-pair state (read and updated as :func:`dcbf_filter_rows_into` does); the
    rows go to ``rows_out``, the rest to ``out`` (each group's fields give units).
    """
    # each group unpacked by position: the caller may pass plain tuples in the groups'
    # order (DcbfFront.run does; module docstring)
    z1, z2, zeta, z3 = deso
    sel, rel_p, rel_v = meas
    u_idx, u_dp, u_dv, u_margin = unsensed
    full, t_tab, since, others_heard = silence
    acc_t, acc_z2 = acc
    a_real, u_prev, a_mean = inner
    a_u, lo_u, hi_u, k_cap = input_rows
    lumped, w, clf, dp, dv, u_try = out
    lumped_into(z1, z2, zeta, prm[F_DESO_H], z3, lumped)
    saturate_into(lumped[1], prm[F_W_MAX], w)
    nominal_into(
        z1, z2, xi, prm[F_TAU_FF], w, prm[F_KP], prm[F_KD], prm[F_LAMBDA], prm[F_KS], False,
        NO_BOX, NO_BOX, prm[F_BRAKE_SHARE], prm[F_RESERVE], clf,
    )
    m, e = sel.shape[0], u_idx.shape[0]
    n = m + e
    pair_rows(sel, rel_p, rel_v, dp, dv)
    pairs = np.empty(n, dtype=np.int64)
    predicted = np.zeros(n, dtype=np.bool_)
    margin = np.zeros(n)
    for r in range(m):
        pairs[r] = sel[r]
    for r in range(e):  # the predicted rows follow the sensed ones
        pairs[m + r] = u_idx[r]
        predicted[m + r] = True
        margin[m + r] = u_margin[r]
        for c in range(3):
            dp[m + r, c] = u_dp[r, c]
            dv[m + r, c] = u_dv[r, c]
    full_out = np.empty(n, dtype=np.bool_)
    acc_out = np.empty((n, 3))
    full_share_rows(pairs, full, t_tab, since, others_heard, full_out)
    neighbour_accel_rows(pairs, acc_t, acc_z2, prm[F_A_MAX], acc_out)
    w_safe = np.empty(3)
    saturate_into(w, prm[F_W_SAFE], w_safe)
    k, h_min = dcbf_filter_rows_into(
        PairRows(dp[:n], dv[:n], pairs, full_out, predicted, margin, acc_out),
        OwnMotion(a_real, u_prev, a_mean, w_safe),
        GroundInput(ground, z1[2] if ground else 0.0, z2[2], floor if ground else 0.0),
        state, rows_out,
    )
    g_out, r_out, side_out = rows_out[0], rows_out[1], rows_out[2]
    for c in range(3):
        u_try[c] = clf[5 + c] + side_out[c]
    held = rows_hold_kernel(a_u, lo_u, hi_u, g_out, r_out, min(k, k_cap), u_try)
    return k, h_min, held


def front_params(ctl: ControllerConfig, tau_ff: float, w_max: float, a_max: float,
                 deso_h: float) -> np.ndarray:
    """The ``prm`` array of :func:`dcbf_front_into` (units at the ``F_*``)."""
    out = np.empty(N_FRONT)
    out[F_TAU_FF], out[F_KP], out[F_KD] = tau_ff, ctl.kp, ctl.kd
    out[F_LAMBDA], out[F_KS] = ctl.clf_lambda, ctl.ks
    out[F_BRAKE_SHARE], out[F_RESERVE] = AW_BRAKE_SHARE, AW_RESERVE
    out[F_W_MAX], out[F_W_SAFE], out[F_A_MAX], out[F_DESO_H] = w_max, W_SAFE, a_max, deso_h
    return out


NO_UNSENSED = Unsensed(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)),
                       np.zeros(0))  # every pair sensed (never written)


def unsensed_rows(
    extra: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
) -> Unsensed:
    """:class:`Unsensed` of :meth:`offboard.agent.unsensed.UnsensedNeighbours.pairs`'s
    (idx, Δp, Δv, margin), or :data:`NO_UNSENSED` for None."""
    if extra is None:
        return NO_UNSENSED
    idx, dp, dv, margin = extra
    return Unsensed(np.asarray(idx, dtype=np.int64), rows3(dp), rows3(dv), f64(margin))


class DcbfFront:
    """One dcbf follower's constant arguments and buffers of :func:`dcbf_front_into`."""

    def __init__(
        self, deso: DESO, filt: DcbfFilter, acc: NeighbourAccel, ctl: ControllerConfig,
        tau_ff: float, w_max: float, dp: np.ndarray, dv: np.ndarray,
    ) -> None:
        """``dp``, ``dv`` (N,3): the follower's buffers for Δp, Δv (rewritten each step)."""
        if filt.qp is None or filt.lag is None:
            raise RuntimeError("DcbfFront: the filter is not configured")
        self.deso, self.filt, self.acc, self.qp = deso, filt, acc, filt.qp
        self.prm = front_params(ctl, tau_ff, w_max, acc.a_max, float(deso.h))
        # dcbf_front_into as run calls it: each group a plain tuple in the order of its
        # NamedTuple's fields. numba types a NamedTuple argument from Python on its slow
        # path (about 2 µs each: with the eight groups the call took twice as long), a
        # plain tuple on its fast one; the kernel unpacks each group by position, so both
        # work. Every array passes a guard or is a buffer of the follower's: one call site
        # (swarm_common.jit.CallSite)
        self._front_call = CallSite(dcbf_front_into)
        # the constant groups as plain tuples, made once
        self._rows_state = tuple(filt.rows_state())
        self._rows_out = tuple(filt.rows_out())
        self.dp, self.dv = dp, dv

    def rebind(self) -> None:
        """Take the filter's row buffers again: :meth:`DcbfFilter.reserve_world
        <offboard.safety.dcbf.filter.DcbfFilter.reserve_world>` replaced them."""
        self._rows_out = tuple(self.filt.rows_out())

    def run(
        self, xi: np.ndarray, meas: tuple[np.ndarray, np.ndarray, np.ndarray],
        silence: tuple[np.ndarray, np.ndarray, float, bool],
        inner: tuple[np.ndarray, np.ndarray, np.ndarray],
        floor: float | None, unsensed: Unsensed = NO_UNSENSED,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, bool, np.ndarray]:
        """One call of :func:`dcbf_front_into` (arguments as there; ``meas``, ``silence``
        and ``inner`` as plain tuples in the order of :class:`Measured`, :class:`Silence`
        and :class:`InnerMotion`, numba's fast path; ``floor`` None: no ground barrier):
        (lumped (2,3), w (3,), clf (CLF_OUT,), K, h_min, held, u_try (3,)). The DESO keeps
        f̂ for its update, as after :meth:`~offboard.estimation.deso.DESO.lumped`; the rows
        are in the filter's buffers."""
        d, qp = self.deso, self.qp
        m = len(meas[0]) + len(unsensed.idx)
        ground = floor is not None
        qp.fit_rows(2 * m + 2 if ground else 2 * m)  # room for every row before the call
        self.filt.note_rows(meas[0], unsensed.idx, ground)  # the rows' layout, as the call's
        self.filt.prepare_trust(inner[0], inner[1])  # the trust region, if any
        lumped, w, clf, u_try = np.empty((2, 3)), np.empty(3), np.empty(CLF_OUT), np.empty(3)
        tab = self.acc.table
        k, h_min, held = self._front_call.call(  # the groups in their order, as plain tuples
            self.prm, (d.z1, d.z2, d.zeta, d.z3), xi, meas, tuple(unsensed),
            silence, (tab.acc_t, tab.acc_z2), inner, ground,
            0.0 if floor is None else float(floor), self._rows_state, self._rows_out,
            (qp.a_u, qp.lo_u, qp.hi_u, qp.m), (lumped, w, clf, self.dp, self.dv, u_try),
        )
        d.adopt_lumped(lumped)
        return lumped, w, clf, k, h_min, held, u_try

    def solve(
        self, u_try: np.ndarray, clf: np.ndarray, k: int, h_min: float, w: np.ndarray,
        held: bool, t0: float, world: bool, v: np.ndarray, a_real: np.ndarray,
        xi: np.ndarray,
    ) -> SafetyOutput:
        """The step's answer from :meth:`run`'s ``u_try``, ``clf``, ``k`` rows, ``h_min``
        and ``held``, and the saturated disturbance ``w`` (``world``: world rows were
        added; ``t0``: the step's clock start, for ``solve_us``). With the transient speed
        limit (docs/safety.md §5i) its rows are prepared from the own odometry velocity
        ``v`` (m/s), the realised acceleration ``a_real`` and the tracked ``xi``; held
        without world rows, ``u_try`` is flown; else the QP checks it against every row."""
        filt = self.filt
        if filt.speed is not None:
            filt.speed.prepare(v, a_real, w, xi)
            return filt.solve_limited(u_try, clf_terms_from(clf), k, h_min, w, self.deso.z2,
                                      held, t0, world)
        if held and not world:
            return SafetyOutput(u_try, h_min, QPStatus.INACTIVE,
                                (time.perf_counter() - t0) * 1e6)
        return filt.solve_rows(u_try, clf_terms_from(clf), k, h_min, w, self.deso.z2,
                               unheld=not held)
