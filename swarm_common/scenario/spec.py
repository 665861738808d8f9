"""The typed view of a validated scenario: :class:`Scenario` and its :class:`AgentSpec`.

Built by :func:`swarm_common.scenario.model.parse_scenario` (which validates and checks the
file first); the checks in :mod:`swarm_common.scenario.checks` and
:mod:`swarm_common.scenario.feasibility` read it, so it imports neither.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from swarm_common.enums import Role
from swarm_common.faults import FaultPlan
from swarm_common.mission.config import MissionConfig, mission_toml
from swarm_common.scenario.schema import (
    SECTIONS,
    CommunicationConfig,
    ControllerConfig,
    DisturbanceConfig,
    FormationConfig,
    LeaderTrajectoryConfig,
    LifecycleConfig,
    ObserverConfig,
    RunConfig,
    SensingConfig,
    UnmodeledConfig,
    VehicleConfig,
    mavlink_id_problem,
    toml_value,
)
from swarm_common.world.config import World, world_toml


# ---------------------------------------------------------------------------
# Typed view
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class AgentSpec:
    """One agent. ``id`` is 1-based and is the MAVLink system id."""

    id: int
    role: Role
    position: np.ndarray  # (3,) ENU m
    velocity: np.ndarray  # (3,) ENU m/s
    vertex: np.ndarray  # (3,) formation vertex (unit-free; bearings come from it)
    cooperative: bool = True  # False: a follower flying its nominal command, no filter

    @property
    def is_leader(self) -> bool:
        return self.role is Role.LEADER


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: one typed, frozen section per TOML table (``sc.controller.kp``)."""

    path: str
    run: RunConfig
    vehicle: VehicleConfig
    disturbance: DisturbanceConfig
    unmodeled: UnmodeledConfig
    formation: FormationConfig
    leader_trajectory: LeaderTrajectoryConfig
    sensing: SensingConfig
    communication: CommunicationConfig
    observer: ObserverConfig
    controller: ControllerConfig
    agents: tuple[AgentSpec, ...]
    lifecycle: LifecycleConfig = LifecycleConfig()
    # [faults] (optional, docs/faults.md): injected transport faults, none by default
    faults: FaultPlan = field(default_factory=FaultPlan)
    # loaded with the feasibility check waived (--allow-infeasible); children inherit it
    allow_infeasible: bool = False
    # loaded with the safety assumptions waived (--allow-unsafe); children inherit it
    allow_unsafe: bool = False
    # [mission] (optional, docs/missions.md): formation waypoints the leaders fly instead of
    # the [leader_trajectory] sinusoid
    mission: MissionConfig | None = None
    # [[obstacle]] and [geofence] (optional, docs/world.md): none by default
    world: World = field(default_factory=World)

    def section(self, name: str) -> Any:
        """The typed section of TOML table ``name`` (``[scenario]`` is :attr:`run`)."""
        return self.run if name == "scenario" else getattr(self, name)

    def to_toml_dict(self) -> dict[str, Any]:
        """The scenario as a TOML document (sections and ``agent`` list)."""
        data: dict[str, Any] = {
            name: {f.name: toml_value(getattr(self.section(name), f.name)) for f in fields(cls)}
            for name, cls in SECTIONS.items()
        }
        data["agent"] = [
            {
                "id": a.id,
                "role": str(a.role),
                "position": a.position.tolist(),
                "velocity": a.velocity.tolist(),
                "vertex": a.vertex.tolist(),
                **({} if a.cooperative else {"cooperative": False}),
            }
            for a in self.agents
        ]
        if self.faults.active:
            data["faults"] = self.faults.as_toml()
        if self.mission is not None:
            data["mission"] = mission_toml(self.mission)
        data |= world_toml(self.world)
        return data

    # Convenience accessors used everywhere --------------------------------
    @property
    def name(self) -> str:
        return self.run.name

    @property
    def seed(self) -> int:
        return self.run.seed

    @property
    def outages(self) -> tuple[tuple[float, float], ...]:
        return self.communication.outages_s

    @property
    def n(self) -> int:
        return len(self.agents)

    @property
    def ids(self) -> list[int]:
        return [a.id for a in self.agents]

    @property
    def leader_ids(self) -> list[int]:
        return [a.id for a in self.agents if a.is_leader]

    @property
    def follower_ids(self) -> list[int]:
        return [a.id for a in self.agents if not a.is_leader]

    @property
    def control_dt(self) -> float:
        return 1.0 / float(self.run.control_hz)

    @property
    def delay_periods(self) -> int:
        """Control periods an estimate arrives later than the next step: a latency L
        (``communication.delay_s``) makes the estimate published at step j usable from the
        first step at or after t_j + L, and never before step j + 1."""
        periods = self.communication.delay_s / self.control_dt
        return max(0, math.ceil(periods - 1e-9) - 1)

    def process_problem(self) -> str | None:
        """Why this scenario cannot fly as processes (daemons, a distributed run), or None:
        a latency (``communication.delay_s``) is modelled in process only; a process's is
        its network's, or a ``[faults]`` delay (docs/faults.md); and every vehicle is a
        MAVLink system, so agent ids above 255 fly in process only."""
        if self.communication.delay_s > 0.0:
            return (f"communication.delay_s = {self.communication.delay_s:g} is modelled in "
                    f"process only (--inproc); processes take their network's latency or a "
                    f"[faults] delay_s")
        return mavlink_id_problem(list(self.ids))

    @property
    def physics_dt(self) -> float:
        return 1.0 / float(self.run.physics_hz)

    @property
    def substeps_per_control(self) -> int:
        return self.run.physics_hz // self.run.control_hz

    @property
    def steps(self) -> int:
        return int(round(self.run.duration_s * self.run.control_hz))

    def index_of(self, agent_id: int) -> int:
        for k, a in enumerate(self.agents):
            if a.id == agent_id:
                return k
        raise KeyError(agent_id)

    def initial_positions(self) -> np.ndarray:
        return np.array([a.position for a in self.agents], dtype=float)

    def initial_velocities(self) -> np.ndarray:
        return np.array([a.velocity for a in self.agents], dtype=float)

    def vertices(self) -> np.ndarray:
        return np.array([a.vertex for a in self.agents], dtype=float)
