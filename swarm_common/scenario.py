"""Scenario files (TOML under ``scenarios/``): schema, validation and typed access.

Every key is declared once in :mod:`swarm_common.scenario_schema` (``SCHEMA``, generated
from one frozen dataclass per section) with its type and allowed range. Loading
rejects an unknown key, a wrong type or an out-of-range value with one
:class:`ScenarioError` line naming the key and what is allowed, e.g.::

    scenarios/bad.toml: controller.gamma = -1.0: must be a number in (0, 100]

Vectors are in the paper's world frame (ENU-style, z up); see docs/conventions.md.
"""

from __future__ import annotations

import logging
import os
import re
import stat
import tomllib
from dataclasses import MISSING, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from swarm_common import graphs
from swarm_common.enums import GraphKind, Role, StartMode
from swarm_common.feasibility import feasibility_problem
from swarm_common.scenario_schema import (
    AGENT_SCHEMA,
    OPTIONAL_SECTIONS,
    SCHEMA,
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
    check_value,
    describe_spec,
    toml_value,
    typed_value,
)

__all__ = [
    "SCHEMA",
    "AgentSpec",
    "CommunicationConfig",
    "ControllerConfig",
    "DisturbanceConfig",
    "FormationConfig",
    "InfeasibleScenarioError",
    "LeaderTrajectoryConfig",
    "LifecycleConfig",
    "ObserverConfig",
    "RunConfig",
    "Scenario",
    "SWARM_NAME_RE",
    "ScenarioError",
    "SensingConfig",
    "UnmodeledConfig",
    "VehicleConfig",
    "load_scenario",
    "parse_scenario",
]


log = logging.getLogger(__name__)

ALLOW_INFEASIBLE_FLAG = "--allow-infeasible"


class ScenarioError(ValueError):
    """A scenario file is missing, unreadable or invalid. ``str()`` is one line."""


class InfeasibleScenarioError(ScenarioError):
    """A valid scenario that the vehicles cannot fly (:mod:`swarm_common.feasibility`);
    ``--allow-infeasible`` turns it into a warning."""


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
    # loaded with the feasibility check waived (--allow-infeasible); children inherit it
    allow_infeasible: bool = False

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
            }
            for a in self.agents
        ]
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

    def with_overrides(self, **sections: dict[str, Any]) -> Scenario:
        """A copy with some keys replaced (validated like a file)."""
        data = self.to_toml_dict()
        for sec, kv in sections.items():
            data.setdefault(sec, {}).update(kv)
        return parse_scenario(data, self.path, self.allow_infeasible)


def parse_scenario(
    data: dict[str, Any], path: str = "<scenario>", allow_infeasible: bool = False
) -> Scenario:
    """Validate a decoded TOML document and return a :class:`Scenario`.

    A valid scenario the vehicles cannot fly (:func:`check_feasible`) raises
    :class:`InfeasibleScenarioError`, or only logs a warning with ``allow_infeasible``."""

    def fail(msg: str) -> ScenarioError:
        return ScenarioError(f"{path}: {msg}")

    for section in data:
        if section != "agent" and section not in SCHEMA:
            raise fail(
                f"unknown section [{section}]; allowed: {', '.join(sorted([*SCHEMA, 'agent']))}"
            )
    raw: dict[str, dict[str, Any]] = {}
    for section, keys in SCHEMA.items():
        given = data.get(section)
        if given is None and section in OPTIONAL_SECTIONS:
            given = {f.name: f.default for f in fields(SECTIONS[section])}
        if given is None:
            raise fail(f"missing section [{section}]")
        if not isinstance(given, dict):
            raise fail(f"[{section}] must be a table")
        for key in given:
            if key not in keys:
                raise fail(f"unknown key {section}.{key}; allowed: {', '.join(keys)}")
        out: dict[str, Any] = {}
        cls_fields = fields(SECTIONS[section])
        defaults = {f.name: f.default for f in cls_fields if f.default is not MISSING}
        for key, spec in keys.items():
            if key not in given and key not in defaults:
                raise fail(f"missing key {section}.{key} ({describe_spec(spec)})")
            v = given[key] if key in given else toml_value(defaults[key])
            if not check_value(v, spec):
                raise fail(f"{section}.{key} = {v!r}: must be {describe_spec(spec)}")
            out[key] = v
        raw[section] = out

    sc = raw["scenario"]
    name_problem = swarm_name_problem(sc["name"])
    if name_problem is not None:
        raise fail(f"scenario.name = {sc['name']!r}: {name_problem}")
    if sc["physics_hz"] % sc["control_hz"] != 0:
        raise fail(
            f"scenario.physics_hz = {sc['physics_hz']}: must be a multiple of "
            f"scenario.control_hz = {sc['control_hz']}"
        )
    veh = raw["vehicle"]
    if veh["thrust_max_n"] <= veh["mass_kg"] * veh["gravity_mps2"]:
        raise fail(
            f"vehicle.thrust_max_n = {veh['thrust_max_n']}: must exceed the weight "
            f"mass_kg * gravity_mps2 = {veh['mass_kg'] * veh['gravity_mps2']:.2f} N"
        )

    agents_raw = data.get("agent")
    if not isinstance(agents_raw, list) or len(agents_raw) < 2:
        raise fail("[[agent]] must list at least 2 agents")
    agents: list[AgentSpec] = []
    seen: set[int] = set()
    for k, a in enumerate(agents_raw):
        where = f"agent[{k}]"
        if not isinstance(a, dict):
            raise fail(f"{where} must be a table")
        for key in a:
            if key not in AGENT_SCHEMA:
                raise fail(f"unknown key {where}.{key}; allowed: {', '.join(AGENT_SCHEMA)}")
        for key, spec in AGENT_SCHEMA.items():
            if key not in a:
                raise fail(f"missing key {where}.{key} ({describe_spec(spec)})")
            if not check_value(a[key], spec):
                raise fail(f"{where}.{key} = {a[key]!r}: must be {describe_spec(spec)}")
        if a["id"] in seen:
            raise fail(f"{where}.id = {a['id']}: duplicate agent id")
        seen.add(a["id"])
        agents.append(
            AgentSpec(
                id=int(a["id"]),
                role=Role(a["role"]),
                position=np.array(a["position"], dtype=float),
                velocity=np.array(a["velocity"], dtype=float),
                vertex=np.array(a["vertex"], dtype=float),
            )
        )
    leaders = raw["formation"]["leaders"]
    if len(set(leaders)) != len(leaders):
        raise fail(f"formation.leaders = {leaders}: duplicate agent id")
    if len(set(leaders)) >= len(agents):
        raise fail(f"formation.leaders = {leaders}: every agent is a leader; need a follower")
    for lid in leaders:
        if lid not in seen:
            raise fail(f"formation.leaders = {leaders}: id {lid} is not an [[agent]] id")
    for a in agents:
        if a.is_leader != (a.id in leaders):
            raise fail(
                f"agent id {a.id}: role = {a.role!r} disagrees with formation.leaders = {leaders}"
            )
    if len(leaders) < 2:
        raise fail(f"formation.leaders = {leaders}: need at least 2 leaders (bearing scale)")
    verts = np.array([a.vertex for a in agents])
    for i in range(len(agents)):
        for j in range(i + 1, len(agents)):
            if np.linalg.norm(verts[i] - verts[j]) < 1e-9:
                raise fail(
                    f"agent ids {agents[i].id} and {agents[j].id} share vertex {verts[i].tolist()}"
                )
    _check_separation(agents, leaders, float(raw["controller"]["d_safe_m"]), fail)
    if raw["lifecycle"]["start"] == StartMode.GROUND:
        _check_pads(agents, float(raw["controller"]["d_safe_m"]), fail)
    typed = {
        ("run" if name == "scenario" else name): cls(
            **{f.name: typed_value(f, raw[name][f.name]) for f in fields(cls)}
        )
        for name, cls in SECTIONS.items()
    }
    scen = Scenario(path=path, agents=tuple(agents), allow_infeasible=allow_infeasible, **typed)
    problem = graph_problem(scen)
    if problem is not None:
        raise fail(problem)
    check_feasible(scen)
    return scen


def check_feasible(sc: Scenario) -> None:
    """Raise :class:`InfeasibleScenarioError` (one line: file, key, numbers) if the vehicles
    cannot fly ``sc`` (:func:`swarm_common.feasibility.feasibility_problem`); with
    ``sc.allow_infeasible`` log it as a warning instead (docs/scenarios.md)."""
    problem = feasibility_problem(sc)
    if problem is None:
        return
    if sc.allow_infeasible:
        log.warning("%s: %s (%s: running it anyway)", sc.path, problem, ALLOW_INFEASIBLE_FLAG)
        return
    raise InfeasibleScenarioError(
        f"{sc.path}: {problem}; pass {ALLOW_INFEASIBLE_FLAG} to run it anyway"
    )


def graph_problem(sc: Scenario) -> str | None:
    """One line naming the ``[formation]`` key if the neighbour graph is unusable, else None
    (docs/graphs.md): ``formation.edges`` listing an unknown id, a self-loop or a pair twice,
    or given with another graph kind; ``knn_k`` ≥ N; an edge longer than
    ``sensing_range_m`` in the desired formation (never sensed there); leaders that do not
    fix every follower or a graph that is not bearing rigid (:func:`graphs.rigidity_problem`)."""
    fm = sc.formation
    if fm.edges and fm.graph is not GraphKind.EDGES:
        return f'formation.edges: only read with formation.graph = "edges" (not "{fm.graph}")'
    if fm.graph is GraphKind.EDGES and not fm.edges:
        return 'formation.edges = []: formation.graph = "edges" needs at least one pair'
    if fm.graph is GraphKind.KNN and fm.knn_k >= sc.n:
        return f"formation.knn_k = {fm.knn_k}: must be below the number of agents ({sc.n})"
    lead = [sc.index_of(i) for i in sc.leader_ids]
    v = sc.vertices()
    spec = graphs.graph_spec(fm, sc.initial_positions(), v, lead)
    try:
        edges = graphs.build_edges(v, spec, sc.ids)
    except ValueError as exc:
        return str(exc)
    far = graphs.long_edges(v, edges, spec.range_vu)
    if far:
        i, j, d = far[0]
        return (
            f"formation.sensing_range_m = {fm.sensing_range_m:g}: {spec.describe()} links ids "
            f"{sc.ids[i]} and {sc.ids[j]}, {d * spec.scale:.2f} m apart in the desired "
            f"formation, never sensed there ({len(far)} edge(s) in all)"
        )
    problem = graphs.rigidity_problem(v, edges, sc.ids, lead)
    return None if problem is None else f"{spec.describe()}: {problem}"


def _check_separation(
    agents: list[AgentSpec], leaders: list[int], d_safe: float, fail: Any
) -> None:
    """Refuse a scenario that is unsafe before it starts: two agents starting closer than
    ``controller.d_safe_m``, or a formation whose vertices, scaled by the leaders'
    separation (Departure 1), put two agents closer than that."""
    p = np.array([a.position for a in agents])
    v = np.array([a.vertex for a in agents])
    k1, k2 = (next(k for k, a in enumerate(agents) if a.id == lid) for lid in leaders[:2])
    scale = float(np.linalg.norm(p[k1] - p[k2]) / np.linalg.norm(v[k1] - v[k2]))
    for i in range(len(agents)):
        for j in range(i + 1, len(agents)):
            d0 = float(np.linalg.norm(p[i] - p[j]))
            if d0 < d_safe:
                raise fail(
                    f"agent[{j}].position = {p[j].tolist()}: starts {d0:.3f} m from agent id "
                    f"{agents[i].id}, closer than controller.d_safe_m = {d_safe:g}"
                )
            dv = scale * float(np.linalg.norm(v[i] - v[j]))
            if dv < d_safe:
                raise fail(
                    f"agent[{j}].vertex = {v[j].tolist()}: {dv:.3f} m from agent id "
                    f"{agents[i].id}'s vertex at the leaders' scale, closer than "
                    f"controller.d_safe_m = {d_safe:g}"
                )


def _check_pads(agents: list[AgentSpec], d_safe: float, fail: Any) -> None:
    """lifecycle.start = "ground": every ``position`` is a pad on the ground (z = 0) and the
    pads are at least 2·``controller.d_safe_m`` apart (the climb columns, offboard.takeoff)."""
    for k, a in enumerate(agents):
        if abs(float(a.position[2])) > 1e-9:
            raise fail(
                f"agent[{k}].position = {a.position.tolist()}: with lifecycle.start = 'ground' "
                f"the position is a pad and its z must be 0"
            )
    for i in range(len(agents)):
        for j in range(i + 1, len(agents)):
            d = float(np.linalg.norm(agents[i].position[:2] - agents[j].position[:2]))
            if d < 2.0 * d_safe - 1e-9:
                raise fail(
                    f"agent[{j}].position = {agents[j].position.tolist()}: pad {d:.3f} m from "
                    f"agent id {agents[i].id}'s, closer than 2 * controller.d_safe_m = "
                    f"{2.0 * d_safe:g} (lifecycle.start = 'ground')"
                )


# The scenario name is the swarm name in every Zenoh key (``swarm/<name>/...``) and part of
# the default run directory: no wildcard (``*``, ``$*``), separator (``/``), ``..``, ``?``
# or ``#`` may reach a key expression or a path.
SWARM_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")
SWARM_NAME_RULE = "1-64 characters of A-Z a-z 0-9 _ -, starting with a letter or digit"
MAX_SCENARIO_BYTES = 1 << 20  # 1 MiB: the shipped scenarios are a few kB
MAX_TOML_NESTING = 32  # arrays/tables deeper than this are refused before tomllib sees them


def swarm_name_problem(name: object) -> str | None:
    """None if ``name`` is a valid swarm/scenario name, else what is wrong (one phrase)."""
    if not isinstance(name, str) or not SWARM_NAME_RE.fullmatch(name):
        return f"must be {SWARM_NAME_RULE}"
    return None


def _nesting_problem(text: str) -> str | None:
    """Bracket depth outside strings and comments, counted before parsing: ``tomllib`` is
    recursive and a file nested thousands deep would raise ``RecursionError``."""
    depth = 0
    quote = ""
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if quote:
            if c == "\\" and quote in ('"', '"""'):
                i += 2
                continue
            if text.startswith(quote, i):
                i += len(quote)
                quote = ""
                continue
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "\"'":
            quote = c * 3 if text.startswith(c * 3, i) else c
            i += len(quote)
            continue
        elif c in "[{":
            depth += 1
            if depth > MAX_TOML_NESTING:
                return f"arrays or tables nested deeper than {MAX_TOML_NESTING}"
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return None


def read_scenario_text(p: Path) -> str:
    """The file's text: a regular file (not a FIFO, device or directory) of at most
    :data:`MAX_SCENARIO_BYTES`, UTF-8, nested at most :data:`MAX_TOML_NESTING` deep."""
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read scenario file ({exc.strerror})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ScenarioError(f"{p}: cannot read scenario file (not a regular file)")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(MAX_SCENARIO_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read scenario file ({exc.strerror})") from None
    finally:
        os.close(fd)
    if len(data) > MAX_SCENARIO_BYTES:
        raise ScenarioError(f"{p}: scenario file larger than {MAX_SCENARIO_BYTES} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{p}: not UTF-8 (byte {exc.start})") from None
    problem = _nesting_problem(text)
    if problem is not None:
        raise ScenarioError(f"{p}: not a valid scenario ({problem})")
    return text


def load_scenario(path: str | Path, allow_infeasible: bool = False) -> Scenario:
    """Read and validate a scenario TOML file (``allow_infeasible``: :func:`parse_scenario`)."""
    p = Path(path)
    text = read_scenario_text(p)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p}: not valid TOML ({exc})") from None
    except RecursionError:
        raise ScenarioError(f"{p}: not a valid scenario (nested too deep)") from None
    return parse_scenario(data, str(p), allow_infeasible)
