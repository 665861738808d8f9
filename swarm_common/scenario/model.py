"""Scenario files (TOML under ``scenarios/``): schema, validation and typed access.

Every key is declared once in :mod:`swarm_common.scenario.schema` (``SCHEMA``, generated
from one frozen dataclass per section) with its type and allowed range. Loading
rejects an unknown key, a wrong type or an out-of-range value with one
:class:`ScenarioError` line naming the key and what is allowed, e.g.::

    scenarios/bad.toml: controller.gamma = -1.0: must be a number in (0, 100]

Vectors are in the paper's world frame (ENU-style, z up); see docs/conventions.md.
"""

from __future__ import annotations

import logging
import tomllib
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

import numpy as np

from swarm_common import faults
from swarm_common.enums import Role, StartMode
from swarm_common.faults import FaultError, FaultPlan
from swarm_common.mission.config import MissionConfig, MissionError, parse_mission
from swarm_common.scenario.files import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    MAX_SCENARIO_BYTES,
    MAX_TOML_NESTING,
    SWARM_NAME_RE,
    SWARM_NAME_RULE,
    InfeasibleScenarioError,
    ScenarioError,
    UnsafeScenarioError,
    dump_toml,
    read_scenario_text,
    swarm_name_problem,
)
from swarm_common.scenario.schema import (
    AGENT_OPTIONAL,
    AGENT_SCHEMA,
    MAX_AGENTS,
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
from swarm_common.scenario.spec import AgentSpec, Scenario
from swarm_common.world.config import WorldError, parse_world

__all__ = [
    "ALLOW_INFEASIBLE_FLAG",
    "ALLOW_UNSAFE_FLAG",
    "UnsafeScenarioError",
    "MAX_SCENARIO_BYTES",
    "MAX_TOML_NESTING",
    "SCHEMA",
    "SWARM_NAME_RULE",
    "FaultPlan",
    "dump_toml",
    "read_scenario_text",
    "swarm_name_problem",
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
    "with_overrides",
]


log = logging.getLogger(__name__)
# top-level tables besides the schema's sections: agents, [faults], [mission], the world
EXTRA_SECTIONS = ("agent", "faults", "mission", "obstacle", "geofence")



def _shown(value: Any, width: int = 40) -> str:
    """``repr(value)`` cut to ``width`` characters (a 400-digit integer stays one short line)."""
    text = repr(value)
    return text if len(text) <= width else f"{text[:width - 3]}..."


def _key(key: str) -> str:
    """A table key as an error shows it: a plain name as it is, anything else (a newline,
    20 000 characters) as :func:`_shown` cuts its ``repr``."""
    plain = key.replace("_", "a").isalnum() and key.isascii() and len(key) <= 64
    return key if plain else _shown(key)


def parse_scenario(
    data: dict[str, Any], path: str = "<scenario>", allow_infeasible: bool = False,
    allow_unsafe: bool = False,
) -> Scenario:
    """Validate a decoded TOML document and return a :class:`Scenario`.

    A valid scenario the vehicles cannot fly (:func:`check_feasible`) raises
    :class:`InfeasibleScenarioError`, or only logs a warning with ``allow_infeasible``; one
    that breaks a load-time safety assumption (:func:`check_safe`) raises
    :class:`UnsafeScenarioError`, or only logs warnings with ``allow_unsafe``."""
    # the checks (graphs, the mission plan, the kernels they run: scipy and numba) are
    # imported here, not with this module: a command line refuses a bad flag or file
    # before it loads a scenario, without paying for them (swarm_common.inputs)
    from swarm_common.scenario.checks import (
        check_feasible,
        check_pads,
        check_safe,
        check_separation,
        graph_problem,
        trust_problem,
    )
    from swarm_common.scenario.graphs import close_pairs
    from swarm_common.scenario.mission_check import mission_problem

    def fail(msg: str) -> ScenarioError:
        return ScenarioError(f"{path}: {msg}")

    for section in data:
        if section not in EXTRA_SECTIONS and section not in SCHEMA:
            allowed = ", ".join(sorted([*SCHEMA, *EXTRA_SECTIONS]))
            raise fail(f"unknown section [{_key(section)}]; allowed: {allowed}")
    mission = _parse_mission(data, fail)
    raw: dict[str, dict[str, Any]] = {}
    for section, keys in SCHEMA.items():
        given = data.get(section)
        if given is None and section == "leader_trajectory" and mission is not None:
            given = {"frequency_hz": 0.0, "amplitude_m": [0.0, 0.0, 0.0]}  # the mission flies
        if given is None and section in OPTIONAL_SECTIONS:
            given = {f.name: f.default for f in fields(SECTIONS[section])}
        if given is None:
            raise fail(f"missing section [{section}]")
        if not isinstance(given, dict):
            raise fail(f"[{section}] must be a table")
        for key in given:
            if key not in keys:
                raise fail(f"unknown key {section}.{_key(key)}; allowed: {', '.join(keys)}")
        out: dict[str, Any] = {}
        cls_fields = fields(SECTIONS[section])
        defaults = {f.name: f.default for f in cls_fields if f.default is not MISSING}
        for key, spec in keys.items():
            if key not in given and key not in defaults:
                raise fail(f"missing key {section}.{key} ({describe_spec(spec)})")
            v = given[key] if key in given else toml_value(defaults[key])
            if not check_value(v, spec):
                raise fail(f"{section}.{key} = {_shown(v)}: must be {describe_spec(spec)}")
            out[key] = v
        raw[section] = out

    sc = raw["scenario"]
    name_problem = swarm_name_problem(sc["name"])
    if name_problem is not None:
        raise fail(f"scenario.name = {_shown(sc['name'])}: {name_problem}")
    if sc["physics_hz"] % sc["control_hz"] != 0:
        raise fail(
            f"scenario.physics_hz = {sc['physics_hz']}: must be a multiple of "
            f"scenario.control_hz = {sc['control_hz']}"
        )
    com = raw["communication"]
    if com["delay_s"] >= com["max_age_s"]:
        raise fail(f"communication.delay_s = {com['delay_s']!r}: must be below "
                   f"communication.max_age_s = {com['max_age_s']!r} (every estimate would "
                   f"arrive too old to use)")
    veh = raw["vehicle"]
    if veh["thrust_max_n"] <= veh["mass_kg"] * veh["gravity_mps2"]:
        raise fail(
            f"vehicle.thrust_max_n = {veh['thrust_max_n']}: must exceed the weight "
            f"mass_kg * gravity_mps2 = {veh['mass_kg'] * veh['gravity_mps2']:.2f} N"
        )

    agents_raw = data.get("agent")
    if not isinstance(agents_raw, list) or len(agents_raw) < 2:
        raise fail("[[agent]] must list at least 2 agents")
    if len(agents_raw) > MAX_AGENTS:
        raise fail(f"[[agent]] lists {len(agents_raw)} agents: at most {MAX_AGENTS}")
    agents: list[AgentSpec] = []
    seen: set[int] = set()
    for k, a in enumerate(agents_raw):
        where = f"agent[{k}]"
        if not isinstance(a, dict):
            raise fail(f"{where} must be a table")
        for key in a:
            if key not in AGENT_SCHEMA and key not in AGENT_OPTIONAL:
                allowed = ", ".join([*AGENT_SCHEMA, *AGENT_OPTIONAL])
                raise fail(f"unknown key {where}.{_key(key)}; allowed: {allowed}")
        for key, spec in AGENT_SCHEMA.items():
            if key not in a:
                raise fail(f"missing key {where}.{key} ({describe_spec(spec)})")
            if not check_value(a[key], spec):
                raise fail(f"{where}.{key} = {_shown(a[key])}: must be {describe_spec(spec)}")
        for key, (spec, _) in AGENT_OPTIONAL.items():
            if key in a and not check_value(a[key], spec):
                raise fail(f"{where}.{key} = {_shown(a[key])}: must be {describe_spec(spec)}")
        cooperative = bool(a.get("cooperative", AGENT_OPTIONAL["cooperative"][1]))
        if not cooperative and a["role"] == Role.LEADER:
            raise fail(f"{where}.cooperative = false: only a follower can be non-cooperative "
                       "(a leader never avoids anyone)")
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
                cooperative=cooperative,
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
                f"agent id {a.id}: role = {str(a.role)!r} disagrees with formation.leaders = "
                f"{leaders}"
            )
    if len(leaders) < 2:
        raise fail(f"formation.leaders = {leaders}: need at least 2 leaders (bearing scale)")
    verts = np.array([a.vertex for a in agents])
    for i, j in sorted(close_pairs(verts, 1e-9)):  # the first pair in index order
        if np.linalg.norm(verts[i] - verts[j]) < 1e-9:
            raise fail(
                f"agent ids {agents[i].id} and {agents[j].id} share vertex {verts[i].tolist()}"
            )
    check_separation(agents, leaders, float(raw["controller"]["d_safe_m"]), fail)
    if raw["lifecycle"]["start"] == StartMode.GROUND:
        check_pads(agents, float(raw["controller"]["d_safe_m"]), fail)
    plan = _parse_faults(data.get("faults", {}), seen, fail)
    typed = {
        ("run" if name == "scenario" else name): cls(
            **{f.name: typed_value(f, raw[name][f.name]) for f in fields(cls)}
        )
        for name, cls in SECTIONS.items()
    }
    lt = typed["leader_trajectory"]
    if mission is not None and lt.frequency_hz > 0.0 and any(lt.amplitude_m):
        raise fail("[mission] and [leader_trajectory] both move the leaders: keep one "
                   "(a mission replaces the sinusoid; remove [leader_trajectory])")
    try:
        world = parse_world(data, float(raw["controller"]["d_safe_m"]))
    except WorldError as exc:
        raise fail(str(exc)) from None
    scen = Scenario(path=path, agents=tuple(agents), allow_infeasible=allow_infeasible,
                    allow_unsafe=allow_unsafe, faults=plan, mission=mission, world=world,
                    **typed)
    problem = trust_problem(scen) or graph_problem(scen)
    if problem is not None:
        raise fail(problem)
    problem = mission_problem(scen)
    if problem is not None:
        raise fail(problem)
    check_feasible(scen)
    check_safe(scen)
    return scen


def _parse_mission(data: dict[str, Any], fail: Any) -> MissionConfig | None:
    """The ``[mission]`` table (:mod:`swarm_common.mission.config`), None when absent."""
    if "mission" not in data:
        return None
    try:
        return parse_mission(data["mission"])
    except MissionError as exc:
        raise fail(str(exc)) from None


def _parse_faults(table: object, ids: set[int], fail: Any) -> FaultPlan:
    """The ``[faults]`` table (:class:`swarm_common.faults.FaultPlan`), per-agent tables
    naming agents of this scenario only."""
    try:
        plan = FaultPlan.parse(table)
    except FaultError as exc:
        raise fail(str(exc)) from None
    for aid in plan.agents:
        if aid not in ids:
            raise fail(f"faults.agent.{aid}: {aid} is not an [[agent]] id")
    return plan


def load_scenario(
    path: str | Path, allow_infeasible: bool = False, allow_unsafe: bool = False
) -> Scenario:
    """Read and validate a scenario TOML file (``allow_infeasible``, ``allow_unsafe``:
    :func:`parse_scenario`).

    Its ``[faults]`` plan becomes this process's (:func:`swarm_common.faults.install`): the
    MAVLink and Zenoh links the process opens afterwards inject those faults."""
    p = Path(path)
    return scenario_from_text(read_scenario_text(p), p, allow_infeasible, allow_unsafe)


def scenario_from_text(
    text: str, path: str | Path, allow_infeasible: bool = False, allow_unsafe: bool = False
) -> Scenario:
    """:func:`load_scenario` of a file's text already read (``path`` only names it in errors
    and in ``Scenario.path``): no file system needed, so a sweep's worker on another machine
    builds the same scenario. Installs its ``[faults]`` plan as :func:`load_scenario` does."""
    p = Path(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p}: not valid TOML ({exc})") from None
    except RecursionError:
        raise ScenarioError(f"{p}: not a valid scenario (nested too deep)") from None
    except ValueError as exc:  # an integer of more than 4300 digits (int's str limit)
        why = str(exc).split(":", 1)[0]
        raise ScenarioError(f"{p}: not a valid scenario ({why})") from None
    sc = parse_scenario(data, str(p), allow_infeasible, allow_unsafe)
    faults.install(sc.faults, sc.seed)  # the transports this process opens apply it
    return sc


def with_overrides(sc: Scenario, **sections: dict[str, Any]) -> Scenario:
    """A copy of ``sc`` with some keys replaced (validated like a file)."""
    data = sc.to_toml_dict()
    for sec, kv in sections.items():
        data.setdefault(sec, {}).update(kv)
    return parse_scenario(data, sc.path, sc.allow_infeasible, sc.allow_unsafe)
