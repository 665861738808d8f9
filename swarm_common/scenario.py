"""Scenario files (TOML under ``scenarios/``): schema, validation and typed access.

Every key is declared once in ``SCHEMA`` with its type and allowed range. Loading
rejects an unknown key, a wrong type or an out-of-range value with one
:class:`ScenarioError` line naming the key and what is allowed, e.g.::

    scenarios/bad.toml: controller.gamma = -1.0: must be a number in (0, 100]

Vectors are in the paper's world frame (ENU-style, z up); see docs/conventions.md.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


class ScenarioError(ValueError):
    """A scenario file is missing, unreadable or invalid. ``str()`` is one line."""


# ---------------------------------------------------------------------------
# Schema: section -> key -> spec. A spec is a tuple
#   ("float", lo, hi, lo_open, hi_open) | ("int", lo, hi) | ("str", choices)
#   ("vec", n, lo, hi)  (list of n numbers) | ("windows",) | ("ids",)
# ---------------------------------------------------------------------------
Spec = tuple[Any, ...]

SCHEMA: dict[str, dict[str, Spec]] = {
    "scenario": {
        "name": ("str", None),
        "seed": ("int", 0, 2**32 - 1),
        "duration_s": ("float", 0.0, 3600.0, True, False),
        "physics_hz": ("int", 50, 5000),
        "control_hz": ("int", 1, 1000),
    },
    "vehicle": {
        "mass_kg": ("float", 0.05, 100.0, False, False),
        "gravity_mps2": ("float", 0.0, 30.0, False, False),
        "thrust_max_n": ("float", 0.0, 5000.0, True, False),
        "tilt_max_deg": ("float", 0.0, 89.0, True, False),
        "tau_rollpitch_s": ("float", 0.0, 5.0, True, False),
        "tau_yaw_s": ("float", 0.0, 5.0, True, False),
        "tau_thrust_s": ("float", 0.0, 5.0, True, False),
        "collision_radius_m": ("float", 0.0, 10.0, True, False),
    },
    "disturbance": {
        "amplitude_n": ("float", 0.0, 100.0, False, False),
        "omega_rad_s": ("float", 0.0, 100.0, False, False),
    },
    "unmodeled": {
        "zeta_nominal": ("vec", 6, -10.0, 10.0),
        "zeta_spread": ("float", 0.0, 1.0, False, False),
        "ground_effect_height_m": ("float", 0.0, 100.0, True, False),
    },
    "formation": {
        "leaders": ("ids",),
        "graph": ("str", ("cube_face_diagonals", "complete")),
        "sensing_range_m": ("float", 0.0, 1000.0, True, False),
    },
    "leader_trajectory": {
        "frequency_hz": ("float", 0.0, 10.0, False, False),
        "amplitude_m": ("vec", 3, -100.0, 100.0),
    },
    "sensing": {
        "bearing_noise_rad": ("float", 0.0, 1.0, False, False),
        "bearing_rate_noise_radps": ("float", 0.0, 10.0, False, False),
        "distance_noise_m": ("float", 0.0, 10.0, False, False),
        "range_rate_noise_mps": ("float", 0.0, 10.0, False, False),
        "dropout_prob": ("float", 0.0, 1.0, False, True),
    },
    "communication": {
        "outages_s": ("windows",),
        "max_age_s": ("float", 0.0, 10.0, True, False),
    },
    "observer": {
        "beta": ("vec", 3, 0.0, 1e4),
        "mu": ("float", 0.0, 100.0, False, False),
        "sigma": ("float", 0.0, 100.0, False, False),
        "substeps": ("int", 1, 100),
        "reference_gain": ("float", 0.0, 1e4, True, False),
        "init_pos_error_m": ("float", 0.0, 100.0, False, False),
        "init_vel_error_mps": ("float", 0.0, 100.0, False, False),
        "leader_anchor": ("float", 0.0, 100.0, False, False),
        "velocity_gain": ("vec", 2, 0.0, 1e4),
    },
    "controller": {
        "method": ("str", ("rcbf", "apf", "none")),
        "kp": ("float", 0.0, 1e4, True, False),
        "kd": ("float", 0.0, 1e4, True, False),
        "clf_lambda": ("float", 0.0, 1e3, True, False),
        "clf_c": ("float", 0.0, 1e3, True, False),
        "rho": ("float", 0.0, 1e9, True, False),
        "u_max_mps2": ("float", 0.0, 100.0, True, False),
        "gamma": ("float", 0.0, 100.0, True, False),
        "tau_safe_s": ("float", 0.0, 10.0, False, False),
        "d_safe_m": ("float", 0.0, 100.0, True, False),
        "apf_gain": ("float", 0.0, 1e4, False, False),
        "apf_velocity_gain": ("float", 0.0, 1e4, False, False),
        "apf_radius_m": ("float", 0.0, 100.0, True, False),
        "leader_kp": ("float", 0.0, 1e3, True, False),
        "leader_kd": ("float", 0.0, 1e3, True, False),
        "ks": ("float", 0.0, 1e3, True, False),
        "deadlock_gain": ("float", 0.0, 100.0, False, False),
        "deadlock_h_m2": ("float", 0.0, 1e3, True, False),
    },
}

AGENT_SCHEMA: dict[str, Spec] = {
    "id": ("int", 1, 255),
    "role": ("str", ("leader", "follower")),
    "position": ("vec", 3, -1e4, 1e4),
    "velocity": ("vec", 3, -100.0, 100.0),
    "vertex": ("vec", 3, -1e3, 1e3),
}


def _describe(spec: Spec) -> str:
    kind = spec[0]
    if kind == "float":
        _, lo, hi, lo_open, hi_open = spec
        return f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if kind == "int":
        return f"an integer in [{spec[1]}, {spec[2]}]"
    if kind == "str":
        return "one of " + ", ".join(repr(c) for c in spec[1]) if spec[1] else "a string"
    if kind == "vec":
        return f"a list of {spec[1]} numbers in [{spec[2]:g}, {spec[3]:g}]"
    if kind == "windows":
        return "a list of [start, end] pairs with 0 <= start < end"
    if kind == "ids":
        return "a non-empty list of agent ids (integers 1..255)"
    raise AssertionError(kind)


def _is_num(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _check(value: Any, spec: Spec) -> bool:
    kind = spec[0]
    if kind == "float":
        _, lo, hi, lo_open, hi_open = spec
        if not _is_num(value) or not math.isfinite(value):
            return False
        ok_lo = value > lo if lo_open else value >= lo
        ok_hi = value < hi if hi_open else value <= hi
        return ok_lo and ok_hi
    if kind == "int":
        is_int = isinstance(value, int) and not isinstance(value, bool)
        return is_int and spec[1] <= value <= spec[2]
    if kind == "str":
        return isinstance(value, str) and (spec[1] is None or value in spec[1])
    if kind == "vec":
        return (
            isinstance(value, list)
            and len(value) == spec[1]
            and all(_is_num(v) and math.isfinite(v) and spec[2] <= v <= spec[3] for v in value)
        )
    if kind == "windows":
        return isinstance(value, list) and all(
            isinstance(w, list)
            and len(w) == 2
            and all(_is_num(x) and math.isfinite(x) for x in w)
            and 0 <= w[0] < w[1]
            for w in value
        )
    if kind == "ids":
        return (
            isinstance(value, list)
            and len(value) > 0
            and all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 255 for v in value)
        )
    raise AssertionError(kind)


# ---------------------------------------------------------------------------
# Typed view
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class AgentSpec:
    """One agent. ``id`` is 1-based and is the MAVLink system id."""

    id: int
    role: str
    position: np.ndarray  # (3,) ENU m
    velocity: np.ndarray  # (3,) ENU m/s
    vertex: np.ndarray  # (3,) formation vertex (unit-free; bearings come from it)

    @property
    def is_leader(self) -> bool:
        return self.role == "leader"


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. Sections are plain dicts of validated values."""

    path: str
    raw: dict[str, dict[str, Any]]
    agents: tuple[AgentSpec, ...]
    outages: tuple[tuple[float, float], ...] = field(default=())

    def __getitem__(self, section: str) -> dict[str, Any]:
        return self.raw[section]

    # Convenience accessors used everywhere --------------------------------
    @property
    def name(self) -> str:
        return str(self.raw["scenario"]["name"])

    @property
    def seed(self) -> int:
        return int(self.raw["scenario"]["seed"])

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
        return 1.0 / float(self.raw["scenario"]["control_hz"])

    @property
    def physics_dt(self) -> float:
        return 1.0 / float(self.raw["scenario"]["physics_hz"])

    @property
    def substeps_per_control(self) -> int:
        return int(self.raw["scenario"]["physics_hz"]) // int(self.raw["scenario"]["control_hz"])

    @property
    def steps(self) -> int:
        sc = self.raw["scenario"]
        return int(round(float(sc["duration_s"]) * sc["control_hz"]))

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
        raw = {k: dict(v) for k, v in self.raw.items()}
        for sec, kv in sections.items():
            raw.setdefault(sec, {}).update(kv)
        data: dict[str, Any] = dict(raw)
        data["agent"] = [
            {
                "id": a.id,
                "role": a.role,
                "position": a.position.tolist(),
                "velocity": a.velocity.tolist(),
                "vertex": a.vertex.tolist(),
            }
            for a in self.agents
        ]
        return parse_scenario(data, self.path)


def parse_scenario(data: dict[str, Any], path: str = "<scenario>") -> Scenario:
    """Validate a decoded TOML document and return a :class:`Scenario`."""

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
        if given is None:
            raise fail(f"missing section [{section}]")
        if not isinstance(given, dict):
            raise fail(f"[{section}] must be a table")
        for key in given:
            if key not in keys:
                raise fail(f"unknown key {section}.{key}; allowed: {', '.join(keys)}")
        out: dict[str, Any] = {}
        for key, spec in keys.items():
            if key not in given:
                raise fail(f"missing key {section}.{key} ({_describe(spec)})")
            v = given[key]
            if not _check(v, spec):
                raise fail(f"{section}.{key} = {v!r}: must be {_describe(spec)}")
            out[key] = float(v) if spec[0] == "float" else v
        raw[section] = out

    sc = raw["scenario"]
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
                raise fail(f"missing key {where}.{key} ({_describe(spec)})")
            if not _check(a[key], spec):
                raise fail(f"{where}.{key} = {a[key]!r}: must be {_describe(spec)}")
        if a["id"] in seen:
            raise fail(f"{where}.id = {a['id']}: duplicate agent id")
        seen.add(a["id"])
        agents.append(
            AgentSpec(
                id=int(a["id"]),
                role=str(a["role"]),
                position=np.array(a["position"], dtype=float),
                velocity=np.array(a["velocity"], dtype=float),
                vertex=np.array(a["vertex"], dtype=float),
            )
        )
    leaders = raw["formation"]["leaders"]
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
    outages = tuple((float(w[0]), float(w[1])) for w in raw["communication"]["outages_s"])
    return Scenario(path=path, raw=raw, agents=tuple(agents), outages=outages)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read scenario file ({exc.strerror})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p}: not valid TOML ({exc})") from None
    return parse_scenario(data, str(p))
