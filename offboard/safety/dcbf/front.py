"""The dcbf follower's step from its state to the QP in one compiled call (issue 11).

Between its measurements and the QP solver a dcbf follower's step (``Method.DCBF``,
:meth:`offboard.agent.follower.FollowerAgent.step`) used to be nine compiled calls, three
dataclasses and two dozen argument conversions from Python. :func:`dcbf_front_into` is
that stretch as one compiled call. It calls the same kernels with the same arguments, in
the same order, so it gives the same bits (``tests/unit/test_dcbf_front.py`` runs whole
missions both ways):

1. the lumped-disturbance estimate ``[f̂, z3 + f̂]``
(:func:`offboard.estimation.deso_kernel.lumped_into`);
2. its saturation at ``W_MAX`` for the controller (:func:`saturate_into`, the same
   in-order sum as :func:`offboard.safety.filter.saturate_norm`);
3. the CLF terms and the nominal control (:func:`offboard.safety.clf_kernel.nominal_into`);
4. Δp, Δv of the pairs (:func:`offboard.estimation.sensing_kernel.pair_rows`);
5. the full-share mask (:func:`offboard.estimation.peer_table.full_share_rows`);
6. the others' accelerations (:func:`offboard.estimation.neighbour_accel.neighbour_accel_rows`);
7. the estimate saturated again at ``W_SAFE`` and the barrier rows
   (:func:`offboard.safety.dcbf.step_kernel.dcbf_filter_rows_into`);
8. the QP's shortcut: whether ``u_nom`` plus the sidestep keeps every row and the input
   set (:func:`offboard.safety.dcbf.kernel.rows_hold_kernel`); in about 70 % of cube8's steps it
   does, and the step needs no solver.

:class:`DcbfFront` keeps the call's constant arguments and output buffers per follower.
The follower takes this path when no pair comes from prediction (docs/safety.md §5c);
otherwise, and for the other methods, it composes the same parts from Python.
"""

from __future__ import annotations

import math

import numpy as np

from offboard.estimation.deso import DESO
from offboard.estimation.deso_kernel import lumped_into
from offboard.estimation.neighbour_accel import NeighbourAccel, neighbour_accel_rows
from offboard.estimation.peer_table import full_share_rows
from offboard.estimation.sensing_kernel import pair_rows
from offboard.safety.clf_kernel import nominal_into
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.kernel import rows_hold_kernel
from offboard.safety.dcbf.step_kernel import dcbf_filter_rows_into
from offboard.safety.filter import W_SAFE
from offboard.safety.rcbf.clf_rcbf import AW_BRAKE_SHARE, AW_RESERVE, CLF_OUT, NO_BOX
from swarm_common.jit import kernel
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

@kernel
def saturate_into(x: np.ndarray, bound: float, out: np.ndarray) -> None:
    """``out`` = x (3,) scaled down to Euclidean norm ``bound`` if longer, else x: the
    bits of :func:`offboard.safety.filter.saturate_norm` (the squares summed in order,
    ``(x0² + x1²) + x2²``; a nan norm leaves x as it is)."""
    n = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if n > bound:
        s = bound / n
        for k in range(3):
            out[k] = x[k] * s
    else:
        for k in range(3):
            out[k] = x[k]


@kernel
def dcbf_front_into(
    prm: np.ndarray, z1: np.ndarray, z2: np.ndarray, zeta: np.ndarray, z3: np.ndarray,
    xi: np.ndarray, sel: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray,
    full: np.ndarray, t_tab: np.ndarray, since: float, others_heard: bool,
    acc_t: np.ndarray, acc_z2: np.ndarray, predicted: np.ndarray, margin: np.ndarray,
    a_real: np.ndarray, u_prev: np.ndarray, a_mean: np.ndarray, ground: bool, floor: float,
    rows_prm: np.ndarray, lag: np.ndarray, sens: np.ndarray, prev_dv: np.ndarray,
    prev_ok: np.ndarray, rel_acc: np.ndarray, rel_ok: np.ndarray, g_out: np.ndarray,
    r_out: np.ndarray, side_out: np.ndarray, a_u: np.ndarray, lo_u: np.ndarray,
    hi_u: np.ndarray, k_cap: int, lumped: np.ndarray, w: np.ndarray, clf: np.ndarray,
    dp: np.ndarray, dv: np.ndarray, full_out: np.ndarray, acc_out: np.ndarray,
    u_try: np.ndarray,
) -> tuple[int, float, bool]:
    """Steps 1–8 of the module docstring; returns (K rows, h_min (m²), held).

    In: ``prm`` (N_FRONT,) the ``F_*`` scalars; the DESO state z1 (m), z2 (m/s), ζ̂ (6,),
    z3 (m/s²); the desired state ξ (12,); the pairs ``sel`` (M,) int64 and the (N,3)
    measured p_j − p_i, v_j − v_i; the full-share inputs (``full`` (N,) bool, the
    stamps ``t_tab`` (N,), ``since`` (s), ``others_heard``); the acceleration slots
    ``acc_t`` (2,N), ``acc_z2`` (2,N,3); (M,) ``predicted`` (all False here) and
    ``margin`` (all 0); the inner-loop model's a_real, u_prev, a_mean (m/s²); the ground
    barrier (``ground``, ``floor`` (m)); the filter's parameters, lag tables and per-pair
    state (read and updated as :func:`dcbf_filter_rows_into` does); the input set rows
    (A_U, lo, hi) and ``k_cap`` the QP's row capacity.

    Out (the caller's buffers): ``lumped`` (2,3) [f̂, z3 + f̂]; ``w`` (3,) the estimate
    saturated at W_MAX; ``clf`` (CLF_OUT,) [V, L_fV, L_gV, u_nom]; Δp, Δv in the first M
    rows of ``dp``, ``dv``; ``full_out`` (M,); ``acc_out`` (M,3); the rows in ``g_out``,
    ``r_out``, the sidestep in ``side_out``; ``u_try`` = u_nom + sidestep.
    """
    lumped_into(z1, z2, zeta, prm[F_DESO_H], z3, lumped)
    saturate_into(lumped[1], prm[F_W_MAX], w)
    nominal_into(
        z1, z2, xi, prm[F_TAU_FF], w, prm[F_KP], prm[F_KD], prm[F_LAMBDA], prm[F_KS], False,
        NO_BOX, NO_BOX, prm[F_BRAKE_SHARE], prm[F_RESERVE], clf,
    )
    m = sel.shape[0]
    pair_rows(sel, rel_p, rel_v, dp, dv)
    full_share_rows(sel, full, t_tab, since, others_heard, full_out)
    neighbour_accel_rows(sel, acc_t, acc_z2, prm[F_A_MAX], acc_out)
    w_safe = np.empty(3)
    saturate_into(w, prm[F_W_SAFE], w_safe)
    k, h_min = dcbf_filter_rows_into(
        dp[:m], dv[:m], sel, full_out, predicted, margin, acc_out, a_real, u_prev, a_mean,
        w_safe, ground, z1[2] if ground else 0.0, z2[2], floor if ground else 0.0,
        rows_prm, lag, sens, prev_dv, prev_ok, rel_acc, rel_ok, g_out, r_out, side_out,
    )
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
        self.rows_state = filt.rows_state()
        self.dp, self.dv = dp, dv

    def run(
        self, xi: np.ndarray, sel: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray,
        full: np.ndarray, t_tab: np.ndarray, since: float, others_heard: bool,
        a_real: np.ndarray, u_prev: np.ndarray, a_mean: np.ndarray, floor: float | None,
        margin: np.ndarray, predicted: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, bool, np.ndarray]:
        """One call of :func:`dcbf_front_into` (arguments as there; ``floor`` None: no
        ground barrier): (lumped (2,3), w (3,), clf (CLF_OUT,), K, h_min, held, u_try
        (3,)). The DESO keeps f̂ for its update, as after
        :meth:`~offboard.estimation.deso.DESO.lumped`; the rows are in the filter's buffers."""
        d, qp = self.deso, self.qp
        m = len(sel)
        ground = floor is not None
        qp.fit_rows(2 * m + 2 if ground else 2 * m)  # as the composed path's solve()
        lumped, w, clf, u_try = np.empty((2, 3)), np.empty(3), np.empty(CLF_OUT), np.empty(3)
        full_out, acc_out = np.empty(m, dtype=np.bool_), np.empty((m, 3))
        tab = self.acc.table
        k, h_min, held = dcbf_front_into(
            self.prm, d.z1, d.z2, d.zeta, d.z3, xi, sel, rel_p, rel_v, full, t_tab, since,
            others_heard, tab.acc_t, tab.acc_z2, predicted, margin, a_real, u_prev, a_mean,
            ground, 0.0 if floor is None else float(floor), *self.rows_state, qp.a_u,
            qp.lo_u, qp.hi_u, qp.m, lumped, w, clf, self.dp, self.dv, full_out, acc_out,
            u_try,
        )
        d.adopt_lumped(lumped)
        return lumped, w, clf, k, h_min, held, u_try
