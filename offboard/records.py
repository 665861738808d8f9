"""The records an agent exchanges: its published estimate, its status and its output.

All vectors ENU, z up (m, m/s, m/s²). These are what :mod:`offboard.agent.factory` exports to the
in-process runner, the daemon and the ground station.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarm_common.enums import Method, QPRow, QPStatus


@dataclass(slots=True)
class NeighbourEstimate:
    """What an agent publishes: its estimate valid at time ``t``."""

    id: int
    t: float
    z1: np.ndarray  # position (leaders: true, predicted)
    z2: np.ndarray  # velocity
    z3: np.ndarray  # lumped disturbance estimate (m/s²)
    xi: np.ndarray  # (12,) desired-state estimate [p*, v*, a*, j*] (leaders: ξ_L)
    is_leader: bool = False
    # False when the agent no longer flies its own safety filter (its vehicle was taken
    # out of offboard, e.g. AUTO.LAND by a third-party client): the others then take the
    # whole avoidance budget against it, as against a leader (docs/safety.md, A5)
    cooperative: bool = True


@dataclass(frozen=True)
class ActiveRows:
    """The safety QP's rows active at its solution (docs/records.md): each row whose
    constraint is tight within :data:`offboard.safety.rcbf.clf_rcbf.ACTIVE_TOL_MPS2`
    (m/s²; barrier rows, relaxed ones included, and input bounds), and the CLF row when
    its slack δ exceeds it. ``count`` rows, the kinds among them (:class:`QPRow` bits) and
    the scenario indices of the other agents whose pair rows are among them (in row
    order, each once). Only a solved QP reports rows: a step the shortcut settled, a
    fallback and the filters without a QP report none (:data:`NO_ACTIVE`)."""

    count: int = 0
    kinds: QPRow = QPRow(0)
    pairs: tuple[int, ...] = ()


NO_ACTIVE = ActiveRows()


@dataclass(slots=True)
class AgentStatus:
    """Per-step status record (for the ground station / metrics)."""

    method: Method
    qp_status: QPStatus = QPStatus.INACTIVE
    # µs of wall clock spent in the QP; for a dcbf step the no-solver test settled in the
    # compiled front call (offboard.safety.dcbf.front), that whole call (rows included)
    solve_us: float = 0.0
    h_min: float = float("inf")
    V: float = 0.0
    slack: float = 0.0  # the CLF row's slack δ (m/s²)
    violation: float = 0.0  # the barrier rows' relaxation σ (m/s²)
    fallbacks: int = 0  # cumulative
    n_sensed: int = 0
    n_used: int = 0
    comm_ok: bool = True
    input_clipped: bool = False  # setpoint conversion changed u (tilt/thrust clip)
    alarms: int = 0  # AgentAlarm bits raised this step (offboard.safety.monitor)
    active: ActiveRows = NO_ACTIVE  # the QP's rows active at its solution
    # the nominal (CLF) control before the safety filter (m/s², ENU; leaders: their u) and
    # the filter's correction ‖u_f − u_nom‖ (m/s²) of its output u_f (the command but for
    # the landing idle, the pad floor and the guard's fallback)
    u_nom: np.ndarray = field(default_factory=lambda: np.zeros(3))
    correction: float = 0.0


@dataclass(slots=True)
class AgentOutput:
    """One control step's result: the setpoint (as decoded from the float32 wire form),
    its MAVLink payload, the ENU virtual control ``u``, the estimate to publish (valid for
    t_{k+1}) and the status. An agent never writes an output, nor an array in it, after
    the step returned it: the in-process runner records outputs in blocks of steps
    (gcs.mission.run_output.AgentRows)."""

    roll: float
    pitch: float
    yaw: float
    thrust_n: float
    q_ned: np.ndarray  # float32 (4,) w, x, y, z
    thrust_norm: np.float32
    u: np.ndarray  # ENU virtual control
    estimate: NeighbourEstimate
    status: AgentStatus
    lumped: np.ndarray = field(default_factory=lambda: np.zeros(3))  # z3 + Φζ̂ (m/s²)
