"""``Method.RCBF``: the paper's CLF–RCBF QP as a safety filter (§4.3–4.4, Departures 12–14).

Per step: the rows of :func:`offboard.safety.rcbf.kernel.rcbf_filter_rows_kernel` in the
QP :class:`offboard.safety.rcbf.clf_rcbf.SafetyQP`.
"""

from __future__ import annotations

import numpy as np

from offboard.records import NO_ACTIVE, ActiveRows
from offboard.safety.base import W_SAFE, SafetyFilter, SafetyInput, SafetyOutput, saturate_norm
from offboard.safety.rcbf.clf_rcbf import ACTIVE_TOL_MPS2, QPResult, SafetyQP
from offboard.safety.rcbf.kernel import rcbf_filter_rows_kernel, rcbf_params
from swarm_common.enums import Method, QPRow
from swarm_common.fastnp import rows3, vec3
from swarm_common.scenario.model import ControllerConfig

QP_INITIAL_PAIRS = 8  # RCBF rows the QP is first built with (grows on demand)


class RcbfFilter(SafetyFilter):
    """CLF–RCBF QP (§4.4): one OSQP problem with room for every other agent."""

    method = Method.RCBF

    def __init__(
        self, ctl: ControllerConfig, u_lo: np.ndarray, u_hi: np.ndarray, leader_mask: np.ndarray
    ) -> None:
        super().__init__(ctl, u_lo, u_hi, leader_mask)
        # grown on demand (offboard.safety.rcbf.clf_rcbf._ClfRowsQP.fit_rows)
        others = len(leader_mask) - 1
        self.qp = SafetyQP(min(others, QP_INITIAL_PAIRS), u_lo, u_hi, ctl.rho, ctl.clf_c,
                           limit=others, solver=ctl.qp_solver)
        if ctl.tau_safe_s <= 0.0:
            raise ValueError("controller.tau_safe_s must be > 0 for the RCBF (relative degree 1)")
        self._params = rcbf_params(ctl.tau_safe_s, ctl.d_safe_m, ctl.gamma, ctl.deadlock_gain,
                                   ctl.deadlock_h_m2)

    @staticmethod
    def _other_accel(x: SafetyInput, lead: list[bool]) -> np.ndarray:
        """(M,3) acceleration of the other agent taken as known: leaders' broadcast a*,
        zero for followers and for leaders not heard from (Departure 13)."""
        a_other = np.zeros((len(lead), 3))
        if x.lead_acc:
            get = x.lead_acc.get
            for r, j in enumerate(x.pairs.tolist()):
                if lead[r] and (a := get(j)) is not None:
                    a_other[r] = a
        return a_other

    def apply(self, x: SafetyInput) -> SafetyOutput:
        """Barrier, deadlock breaker, shares and rows in one compiled call
        (:func:`offboard.safety.rcbf.kernel.rcbf_filter_rows_kernel`), then the QP. The own
        disturbance enters the rows saturated at W_SAFE, so a start-up transient of the
        observer cannot cancel a safety row."""
        lm = self.leader_mask[x.pairs]  # follower–follower pairs split the budget
        n_hat, rhs, h, side = rcbf_filter_rows_kernel(
            rows3(x.dp), rows3(x.dv), lm, self._other_accel(x, lm.tolist()),
            vec3(saturate_norm(x.w, W_SAFE)), self._params,
        )
        gain = self.qp.brake_gain
        res = self.qp.solve(x.clf.u_nom + side, x.clf, n_hat, rhs, h,
                            lambda: -x.w - gain * x.z2)  # the fallback, formed if taken
        return SafetyOutput(
            res.u, res.h_min, res.status, res.solve_us, res.slack, res.violation, res.fallback,
            active_rows(res, x.pairs),
        )


def active_rows(res: QPResult, pairs: np.ndarray) -> ActiveRows:
    """The rows active at ``res``'s solution: row r the pair with the agent of scenario
    index ``pairs[r]``, the box's bounds the input rows; none unless the QP was solved."""
    if res.tight is None:
        return NO_ACTIVE
    kinds = QPRow.PAIR if len(res.tight) else QPRow(0)
    if res.tight_input:
        kinds |= QPRow.INPUT
    clf = res.slack > ACTIVE_TOL_MPS2
    if clf:
        kinds |= QPRow.CLF
    return ActiveRows(len(res.tight) + res.tight_input + int(clf), kinds,
                      tuple(int(pairs[r]) for r in res.tight.tolist()))
