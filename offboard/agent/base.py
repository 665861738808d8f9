"""What leaders and followers share: identity, timing, the control box, the inner-loop
model of the attitude/thrust lags, the method switch and the output record."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from offboard.agent.landing import LANDED_Z, LandingPlan, LandingReference, landed
from offboard.agent.takeoff import TakeoffPlan, is_ground_start, takeoff_plan
from offboard.estimation.peer_table import EstimateBatch
from offboard.inner_loop.attitude import InnerLoopModel, Setpoint
from offboard.records import AgentOutput, AgentStatus, NeighbourEstimate
from offboard.safety.filter import parse_method
from swarm_common.enums import Method
from swarm_common.scenario.input_set import control_box
from swarm_common.scenario.model import Scenario

CLIP_TOL = 1e-3  # m/s², a setpoint realising u farther than this counts as input_clipped


class AgentBase(ABC):
    """Setup common to every agent of scenario ``sc``; subclasses implement the step.

    ``step(k, t, truth_p, truth_v, neighbours, comm_ok)`` is called once per control
    period ``dt`` (s) at t_k and returns the setpoint for [t_k, t_{k+1}).
    """

    is_leader: ClassVar[bool]

    def __init__(self, sc: Scenario, agent_id: int, method: Method | str | None) -> None:
        self.sc = sc
        self.id = agent_id
        self.index = sc.index_of(agent_id)
        self.dt = sc.control_dt
        self.veh = sc.vehicle
        # a non-cooperative follower ([[agent]] cooperative = false) flies its nominal
        # command with no filter, whatever the run's method, and says so in its estimates
        self.cooperative = bool(sc.agents[self.index].cooperative)
        self.method = parse_method(method or sc.controller.method)
        if not self.cooperative:
            self.method = Method.NONE
        self.substeps = sc.observer.substeps
        self.inner = InnerLoopModel(self.veh, self.dt / self.substeps)
        self.u_lo, self.u_hi = control_box(sc.vehicle, sc.controller)
        self.yaw = 0.0
        self.landing: LandingReference | None = None
        # ground start (offboard.agent.takeoff): the common take-off plan, else None
        self.takeoff: TakeoffPlan | None = takeoff_plan(sc) if is_ground_start(sc) else None
        # held on the pad until start_takeoff (a real-time swarm the operator starts)
        self.takeoff_held = False

    def set_method(self, method: Method | str) -> None:
        """Switch the collision-avoidance method (at run time); ValueError if unknown. A
        non-cooperative agent keeps flying without a filter."""
        chosen = parse_method(method)
        if self.cooperative:
            self.method = chosen

    def start_landing(self, plan: LandingPlan) -> None:
        """Switch to the coordinated land-all of ``plan`` (offboard.agent.landing) from the current
        reference at ``plan.t_land``; the safety filter stays active. Idempotent."""
        if self.landing is None:
            self.landing = LandingReference(plan, self.index, self.current_reference(plan.t_land))

    def hold_for_takeoff(self) -> bool:
        """Ground start: stay idle on the pad (as landed) until :meth:`start_takeoff`; call
        it before the first step. False (nothing changes) for an airborne start."""
        if self.takeoff is None:
            return False
        self.takeoff_held = True
        return True

    def start_takeoff(self, t0: float) -> bool:
        """Start the held coordinated take-off with its climbs at mission time ``t0`` (s,
        the same on every agent: offboard.agent.takeoff). True if it started now; False when
        there is nothing held (airborne start, already started, or landing). Raises
        ValueError for a negative or non-finite ``t0``."""
        if self.takeoff is None or not self.takeoff_held or self.landing is not None:
            return False
        self.takeoff = takeoff_plan(self.sc, t0)
        self.takeoff_held = False
        return True

    def in_formation_phase(self, t: float) -> bool:
        """Flying the formation at ``t`` (s): after a ground start's take-off plan hands
        over to the trajectory (``t_traj``), before any land-all."""
        if self.landing is not None:
            return False
        return self.takeoff is None or (
            not self.takeoff_held and self.takeoff_clock(t) >= self.takeoff.t_traj)

    def takeoff_clock(self, t: float) -> float:
        """The time at which to read the take-off plan: ``t``, or the plan's start (pad at
        rest) while held."""
        if self.takeoff is not None and self.takeoff_held:
            return self.takeoff.t0
        return t

    def landed_idle(self, t: float, z: float, u: np.ndarray) -> np.ndarray:
        """``u``, or the idle command (lowest vertical acceleration, no tilt) once the landing
        reference ended and the altitude ``z`` (m) is below offboard.agent.landing.LANDED_Z."""
        if landed(self.landing, t, z):
            return np.array([0.0, 0.0, self.u_lo[2]])
        return u

    def on_pad_floor(self, t: float, z: float, u: np.ndarray) -> np.ndarray:
        """``u`` with its vertical part at least 0 (hover thrust) while on the pad during the
        take-off climb (t < t_climb, altitude ``z`` (m) below offboard.agent.landing.LANDED_Z): the
        ground contact does not realise a downward command, and the filters' inner-loop
        model (dcbf) would otherwise predict an acceleration that does not happen. While
        held for the take-off (:meth:`hold_for_takeoff`): the idle command."""
        if self.takeoff_held and self.landing is None:
            return np.array([0.0, 0.0, self.u_lo[2]])
        if self.takeoff is None or t >= self.takeoff.t_climb or z >= LANDED_Z or u[2] >= 0.0:
            return u
        return np.array([u[0], u[1], 0.0])

    @abstractmethod
    def current_reference(self, t: float) -> np.ndarray:
        """ξ = [p*, v*, a*, j*] (12,) this agent tracks at t."""

    @abstractmethod
    def initial_estimate(self) -> NeighbourEstimate:
        """The estimate valid for t_0 (published before the first step)."""

    @abstractmethod
    def step(
        self,
        k: int,
        t: float,
        truth_p: np.ndarray,
        truth_v: np.ndarray,
        neighbours: Mapping[int, NeighbourEstimate] | EstimateBatch,
        comm_ok: bool = True,
    ) -> AgentOutput:
        """One control step at t_k (see :mod:`offboard.agent.factory`)."""

    @staticmethod
    def _output(
        sp: Setpoint, u: np.ndarray, est: NeighbourEstimate, status: AgentStatus,
        lumped: np.ndarray,
    ) -> AgentOutput:
        return AgentOutput(
            sp.roll, sp.pitch, sp.yaw, sp.thrust_n, sp.q_ned, sp.thrust_norm, u, est, status,
            lumped=lumped,
        )
