"""Safety filters: how a follower turns the nominal control into the applied one.

One class per collision-avoidance method (:class:`swarm_common.enums.Method`), found
through :data:`SAFETY_FILTERS`; a new method plugs in by adding a ``Method`` member and
one :class:`SafetyFilter` subclass decorated with :func:`register_filter`. Every filter
starts from the same nominal formation controller ``u_nom`` (paper §4.2, Departure 10):

* ``rcbf``: CLF–RCBF QP (§4.3–4.4, Departures 12–14) of :mod:`offboard.safety.rcbf.clf_rcbf`;
* ``apf``: improved artificial potential field (§5.4, Departure 17) of :mod:`offboard.safety.apf`;
* ``dcbf``: CLF + sampled-data CBF QP over the realisable input set
  (:mod:`offboard.safety.dcbf.filter`, docs/safety.md);
* ``none``: the nominal control clipped to the box.

Pairs are rows of Δp = p_i − p_j (m), Δv = v_i − v_j (m/s) over the sensed agents j.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar, TypeVar

import numpy as np

from offboard.safety.apf import apf_control, none_control
from offboard.safety.rcbf.clf_rcbf import ClfTerms, SafetyQP, barrier, tangential_term
from offboard.safety.rcbf.kernel import rcbf_filter_rows_kernel, rcbf_params
from swarm_common.enums import Method, QPStatus
from swarm_common.fastnp import einsum, rows3, vec3
from swarm_common.scenario.model import ControllerConfig

W_SAFE = 0.5  # m/s², bound on the lumped-disturbance estimate inside the RCBF rows
QP_INITIAL_PAIRS = 8  # RCBF rows the QP is first built with (grows on demand)


def parse_method(method: Method | str) -> Method:
    """``method`` as a :class:`Method`; ValueError naming the choices if it is not one."""
    try:
        return Method(method)
    except ValueError:
        choices = ", ".join(m.value for m in Method)
        raise ValueError(f"unknown method {method!r}; use one of {choices}") from None


def saturate_norm(x: np.ndarray, bound: float) -> np.ndarray:
    """``x`` scaled down to Euclidean norm ``bound`` if longer (same array otherwise).

    A 3-vector's squared norm is summed in order in Python floats, ``(x0² + x1²) + x2²``:
    a third of the cost of numpy's ``dot`` call, and the same bits as the OpenBLAS ``ddot``
    this project was measured with (400 000 of 400 000 random vectors; docs/performance.md,
    fifteenth round). Other shapes take ``dot``."""
    if x.shape == _VEC3 and x.dtype.char == "d":  # float64, either byte order
        a, b, c = x.tolist()
        n = math.sqrt(a * a + b * b + c * c)
    else:
        n = math.sqrt(float(x.dot(x)))  # numpy's dot, as x @ x but a cheaper call
    return x * (bound / n) if n > bound else x


_VEC3 = (3,)


@dataclass
class SafetyInput:
    """What a filter sees at t_k (ENU)."""

    clf: ClfTerms  # CLF terms and nominal control u_nom (m/s²)
    w: np.ndarray  # own lumped disturbance estimate, saturated (m/s²)
    z2: np.ndarray  # own velocity estimate (m/s)
    dp: np.ndarray  # (M,3) Δp = p_i − p_j over the sensed pairs (m)
    dv: np.ndarray  # (M,3) Δv = v_i − v_j (m/s)
    pairs: np.ndarray  # (M,) scenario index j of each row
    lead_acc: dict[int, np.ndarray]  # broadcast desired acceleration of leaders (m/s²)
    # dcbf only: own realised virtual control of the inner-loop model (m/s²), the
    # previous command (m/s²) and the others' estimated actual accelerations (M,3)
    a_real: np.ndarray = field(default_factory=lambda: np.zeros(3))
    u_prev: np.ndarray = field(default_factory=lambda: np.zeros(3))
    a_mean: np.ndarray = field(default_factory=lambda: np.zeros(3))  # realised, last period
    other_acc: np.ndarray | None = None
    # (M,) True where this agent takes the whole avoidance budget (the other is a leader
    # or does not cooperate); None: leaders only (the filter's leader mask)
    full_share: np.ndarray | None = None
    # dcbf only: own position estimate (m) and the ground barrier's floor altitude (m);
    # floor None = no ground barrier (on the pad, taking off below the floor, landing)
    z1: np.ndarray | None = None
    floor_m: float | None = None
    # dcbf only: (M,) distance margin (m) added to D per row: 0 for sensed pairs, the
    # prediction error bound for a neighbour that is not sensed now (docs/safety.md §5c)
    margin: np.ndarray | None = None
    predicted: np.ndarray | None = None  # (M,) True for rows from prediction, not sensing


@dataclass
class SafetyOutput:
    """The applied control and what the status record reports about the step."""

    u: np.ndarray  # ENU virtual control (m/s²), inside the box
    h_min: float = math.inf  # smallest barrier value h_ij (m²), inf without pairs
    qp_status: QPStatus = QPStatus.INACTIVE
    solve_us: float = 0.0
    slack: float = 0.0  # CLF slack δ
    violation: float = 0.0  # RCBF relaxation σ
    fallback: bool = False  # counted in the agent's fallbacks


class SafetyFilter(ABC):
    """Base: the controller parameters, the box [u_lo, u_hi] and which agents lead."""

    method: ClassVar[Method]

    def __init__(
        self, ctl: ControllerConfig, u_lo: np.ndarray, u_hi: np.ndarray, leader_mask: np.ndarray
    ) -> None:
        self.ctl = ctl
        self.u_lo = u_lo
        self.u_hi = u_hi
        self.leader_mask = leader_mask

    @abstractmethod
    def apply(self, x: SafetyInput) -> SafetyOutput:
        """The control to apply for this step."""

    def _barrier(self, x: SafetyInput) -> np.ndarray:
        """h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D² per pair (§2.3)."""
        return barrier(x.dp, x.dv, self.ctl.tau_safe_s, self.ctl.d_safe_m)

    def _sidestep(self, x: SafetyInput, h: np.ndarray) -> np.ndarray:
        """Deadlock breaker shared by rcbf and apf
        (:func:`~offboard.safety.rcbf.clf_rcbf.tangential_term`)."""
        return tangential_term(x.dp, h, self.ctl.deadlock_gain, self.ctl.deadlock_h_m2)


SAFETY_FILTERS: dict[Method, type[SafetyFilter]] = {}
_F = TypeVar("_F", bound=type[SafetyFilter])


def register_filter(cls: _F) -> _F:
    """Class decorator: make ``cls`` the filter of ``cls.method``."""
    SAFETY_FILTERS[cls.method] = cls
    return cls


@register_filter
class NoFilter(SafetyFilter):
    """No collision avoidance: ``u = clip(u_nom)``; h is only reported."""

    method = Method.NONE

    def apply(self, x: SafetyInput) -> SafetyOutput:
        u = none_control(x.clf.u_nom, self.u_lo, self.u_hi)
        h_min = float(self._barrier(x).min()) if len(x.pairs) else math.inf
        return SafetyOutput(u, h_min=h_min)


@register_filter
class ApfFilter(SafetyFilter):
    """Improved APF: ``u = clip(u_nom + Σ u_rep + u_side)`` (§5.4, Departure 17)."""

    method = Method.APF

    def apply(self, x: SafetyInput) -> SafetyOutput:
        ctl = self.ctl
        h = self._barrier(x)
        side = self._sidestep(x, h)
        dp, dv = x.dp, x.dv
        dd = einsum("ij,ij->i", dp, dv) / np.maximum(
            np.sqrt(einsum("ij,ij->i", dp, dp)), 1e-6
        )  # range rate ḋ_ij (negative when closing)
        u = apf_control(
            x.clf.u_nom, dp, dd, side, ctl.apf_gain,
            ctl.apf_velocity_gain, ctl.apf_radius_m, self.u_lo, self.u_hi,
        )
        return SafetyOutput(u, h_min=float(h.min()) if len(h) else math.inf)


@register_filter
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
            res.u, res.h_min, res.status, res.solve_us, res.slack, res.violation, res.fallback
        )


def make_filters(
    ctl: ControllerConfig, u_lo: np.ndarray, u_hi: np.ndarray, leader_mask: np.ndarray
) -> dict[Method, SafetyFilter]:
    """One filter per registered method (kept for the agent's lifetime: a method switch
    keeps each filter's state, e.g. the QP's warm start)."""
    return {m: cls(ctl, u_lo, u_hi, leader_mask) for m, cls in SAFETY_FILTERS.items()}


# the dcbf filter registers itself on import (kept in its own module)
import offboard.safety.dcbf.filter  # noqa: E402,F401
