"""What every safety filter shares: its input, its output and its base class.

A filter (:class:`SafetyFilter`) turns the nominal control of a step into the applied
one; the classes per method are in :mod:`offboard.safety.apf` (``none``, ``apf``),
:mod:`offboard.safety.rcbf.filter` and :mod:`offboard.safety.dcbf.filter`, and
:func:`offboard.safety.filter.make_filters` makes one of each. Pairs are rows of
Δp = p_i − p_j (m), Δv = v_i − v_j (m/s) over the sensed agents j.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from offboard.records import NO_ACTIVE, ActiveRows, AgentStatus
from offboard.safety.rcbf.clf_rcbf import ClfTerms, barrier, tangential_term
from swarm_common.enums import Method, QPStatus
from swarm_common.scenario.model import ControllerConfig

W_SAFE = 0.5  # m/s², bound on the lumped-disturbance estimate inside the RCBF rows


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


@dataclass(slots=True)
class SafetyOutput:
    """The applied control and what the status record reports about the step."""

    u: np.ndarray  # ENU virtual control (m/s²), inside the box
    h_min: float = math.inf  # smallest barrier value h_ij (m²), inf without pairs
    qp_status: QPStatus = QPStatus.INACTIVE
    solve_us: float = 0.0
    slack: float = 0.0  # CLF slack δ (m/s²)
    violation: float = 0.0  # relaxation σ of the barrier rows (m/s²)
    fallback: bool = False  # counted in the agent's fallbacks
    active: ActiveRows = NO_ACTIVE  # the QP's rows active at its solution (the record's)

    def report_into(self, status: AgentStatus, u: np.ndarray) -> None:
        """This step's QP report into the agent's ``status``, with the correction
        ‖u − u_nom‖ (m/s²) of the command ``u`` it flies from ``status.u_nom``."""
        status.qp_status, status.solve_us, status.h_min = self.qp_status, self.solve_us, self.h_min
        status.slack, status.violation, status.active = self.slack, self.violation, self.active
        (a, b, c), (x, y, z) = u.tolist(), status.u_nom.tolist()
        status.correction = math.sqrt((a - x) * (a - x) + (b - y) * (b - y) + (c - z) * (c - z))


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
