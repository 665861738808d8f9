"""Scenario schema: one frozen dataclass per TOML section, each field with its spec.

``SCHEMA`` (section -> key -> spec) is generated from the dataclasses, so the typed view
(``sc.controller.kp``) and the validation in :mod:`swarm_common.scenario.model` cannot disagree.
Units are in the field names (``_s``, ``_m``, ``_mps2``, ``_hz``, ``_deg``, ``_n``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from enum import StrEnum
from typing import Any

from swarm_common.enums import GraphKind, Method, NoiseDraws, QPSolver, Role, StartMode
from swarm_common.inputs import is_finite_number
from swarm_common.ports import MAX_ID

# ---------------------------------------------------------------------------
# Schema. Each section is a frozen dataclass; each field carries its spec in its
# metadata, and ``SCHEMA`` is generated from the dataclasses, so the typed view and
# the validation cannot disagree. A spec is a tuple
#   ("float", lo, hi, lo_open, hi_open) | ("int", lo, hi) | ("str", choices)
#   ("vec", n, lo, hi)  (list of n numbers) | ("windows",) | ("ids",) | ("pairs",)
# A field with a default may be left out of its table (the default applies).
# ---------------------------------------------------------------------------
Spec = tuple[Any, ...]


def _num(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False) -> Any:
    return field(metadata={"spec": ("float", lo, hi, lo_open, hi_open)})


def _int(lo: int, hi: int) -> Any:
    return field(metadata={"spec": ("int", lo, hi)})


def _vec(n: int, lo: float, hi: float) -> Any:
    return field(metadata={"spec": ("vec", n, lo, hi)})


def _choice(enum: type[StrEnum] | None) -> Any:
    return field(metadata={"spec": ("str", tuple(enum) if enum else None), "enum": enum})


def _special(kind: str) -> Any:
    return field(metadata={"spec": (kind,)})


@dataclass(frozen=True)
class RunConfig:
    """``[scenario]``: name, seed and clocks."""

    name: str = _choice(None)
    seed: int = _int(0, 2**32 - 1)
    duration_s: float = _num(0.0, 3600.0, lo_open=True)  # s
    physics_hz: int = _int(50, 5000)  # Hz, fixed-step integration of the dynamics
    control_hz: int = _int(1, 1000)  # Hz, one setpoint per control step
    formation_deadline_s: float = _num(0.0, 3600.0)  # s, start of the tracking-metric window


@dataclass(frozen=True)
class VehicleConfig:
    """``[vehicle]``: airframe and inner-loop model (paper 2.1)."""

    mass_kg: float = _num(0.05, 100.0)
    gravity_mps2: float = _num(0.0, 30.0)
    thrust_max_n: float = _num(0.0, 5000.0, lo_open=True)
    tilt_max_deg: float = _num(0.0, 89.0, lo_open=True)
    tau_rollpitch_s: float = _num(0.0, 5.0, lo_open=True)
    tau_yaw_s: float = _num(0.0, 5.0, lo_open=True)
    tau_thrust_s: float = _num(0.0, 5.0, lo_open=True)
    collision_radius_m: float = _num(0.0, 10.0, lo_open=True)


@dataclass(frozen=True)
class DisturbanceConfig:
    """``[disturbance]``: d(t) = [A cos wt, A sin wt, A sin wt] N (paper 5.1)."""

    amplitude_n: float = _num(0.0, 100.0)
    omega_rad_s: float = _num(0.0, 100.0)


@dataclass(frozen=True)
class UnmodeledConfig:
    """``[unmodeled]``: f~ = Phi(p, v) zeta (paper 2.2), m/s^2 per regressor unit."""

    zeta_nominal: tuple[float, ...] = _vec(6, -10.0, 10.0)
    zeta_spread: float = _num(0.0, 1.0)
    ground_effect_height_m: float = _num(0.0, 100.0, lo_open=True)


@dataclass(frozen=True)
class FormationConfig:
    """``[formation]``: leaders, neighbour graph and sensing range (docs/graphs.md);
    ``knn_k`` (graph "knn") and ``edges`` (graph "edges", pairs of agent ids) are optional."""

    leaders: tuple[int, ...] = _special("ids")
    graph: GraphKind = _choice(GraphKind)
    sensing_range_m: float = _num(0.0, 1000.0, lo_open=True)
    knn_k: int = field(default=6, metadata={"spec": ("int", 1, 254)})
    edges: tuple[tuple[int, int], ...] = field(default=(), metadata={"spec": ("pairs",)})


@dataclass(frozen=True)
class LeaderTrajectoryConfig:
    """``[leader_trajectory]``: p_L(t) = p_L(0) + A (1 - cos wt), w = 2 pi f."""

    frequency_hz: float = _num(0.0, 10.0)
    amplitude_m: tuple[float, ...] = _vec(3, -100.0, 100.0)


@dataclass(frozen=True)
class SensingConfig:
    """``[sensing]``: noise standard deviations, per-pair dropout probability and which
    pairs draw noise (``noise_draws``, optional; docs/scenarios.md)."""

    bearing_noise_rad: float = _num(0.0, 1.0)
    bearing_rate_noise_radps: float = _num(0.0, 10.0)
    distance_noise_m: float = _num(0.0, 10.0)
    range_rate_noise_mps: float = _num(0.0, 10.0)
    dropout_prob: float = _num(0.0, 1.0, hi_open=True)
    noise_draws: NoiseDraws = field(
        default=NoiseDraws.EVERY_AGENT,
        metadata={"spec": ("str", tuple(NoiseDraws)), "enum": NoiseDraws},
    )


@dataclass(frozen=True)
class CommunicationConfig:
    """``[communication]``: outage windows (s), neighbour-data ageing (s) and the latency of
    the neighbours' estimates (s; optional, 0: the next step; modelled in process,
    docs/faults.md "Link latency in process")."""

    outages_s: tuple[tuple[float, float], ...] = _special("windows")
    max_age_s: float = _num(0.0, 10.0, lo_open=True)
    delay_s: float = field(default=0.0, metadata={"spec": ("float", 0.0, 5.0, False, False)})


@dataclass(frozen=True)
class ObserverConfig:
    """``[observer]``: DESO (paper 3) and desired-state observer (paper 4.1) gains."""

    beta: tuple[float, ...] = _vec(3, 0.0, 1e4)
    mu: float = _num(0.0, 100.0)
    sigma: float = _num(0.0, 100.0)
    substeps: int = _int(1, 100)
    reference_gain: float = _num(0.0, 1e4, lo_open=True)
    init_pos_error_m: float = _num(0.0, 100.0)
    init_vel_error_mps: float = _num(0.0, 100.0)
    leader_anchor: float = _num(0.0, 100.0)
    velocity_gain: tuple[float, ...] = _vec(2, 0.0, 1e4)


@dataclass(frozen=True)
class ControllerConfig:
    """``[controller]``: CLF (paper 4.2), RCBF (4.3), APF baseline and leader PD."""

    method: Method = _choice(Method)
    kp: float = _num(0.0, 1e4, lo_open=True)
    kd: float = _num(0.0, 1e4, lo_open=True)
    clf_lambda: float = _num(0.0, 1e3, lo_open=True)
    clf_c: float = _num(0.0, 1e3, lo_open=True)
    rho: float = _num(0.0, 1e9, lo_open=True)
    u_max_mps2: float = _num(0.0, 100.0, lo_open=True)
    gamma: float = _num(0.0, 100.0, lo_open=True)
    tau_safe_s: float = _num(0.0, 10.0)
    d_safe_m: float = _num(0.0, 100.0, lo_open=True)
    apf_gain: float = _num(0.0, 1e4)
    apf_velocity_gain: float = _num(0.0, 1e4)
    apf_radius_m: float = _num(0.0, 100.0, lo_open=True)
    leader_kp: float = _num(0.0, 1e3, lo_open=True)
    leader_kd: float = _num(0.0, 1e3, lo_open=True)
    ks: float = _num(0.0, 1e3, lo_open=True)
    deadlock_gain: float = _num(0.0, 100.0)
    deadlock_h_m2: float = _num(0.0, 1e3, lo_open=True)
    # dcbf (docs/safety.md): class-K  alpha(h) = g_lin h + g_cubic h^3, acceleration error
    # bound of the prediction, K sides of the tilt-cone polytope
    dcbf_gamma_lin: float = _num(0.0, 100.0)
    dcbf_gamma_cubic: float = _num(0.0, 100.0)
    dcbf_accel_error_mps2: float = _num(0.0, 10.0)
    dcbf_cone_sides: int = _int(3, 64)
    # dcbf: altitude (m) below which an airborne follower may not descend (ground barrier)
    dcbf_ground_clearance_m: float = _num(0.0, 100.0)
    # dcbf trust region (optional; docs/safety.md 5f): J (m/s²), the bound on the command
    # jump |u - a0|_inf of a tight QP whose rows carry a margin from the measured lag-model
    # error for that jump plus dcbf_trust_error_mps2 (the noise and estimate part); 0 = off
    dcbf_trust_jump_mps2: float = field(
        default=0.0, metadata={"spec": ("float", 0.0, 10.0, False, False)}
    )
    dcbf_trust_error_mps2: float = field(
        default=0.0, metadata={"spec": ("float", 0.0, 10.0, False, False)}
    )
    # dcbf pair barrier taller than wide (optional; docs/safety.md §4c): κ ≥ 1 scales the
    # barrier's vertical axis, safe set outside the ellipsoid of semi-axes (D, D, κD),
    # for the downwash below a quadrotor; 1 = the sphere
    dcbf_vertical_scale: float = field(
        default=1.0, metadata={"spec": ("float", 1.0, 10.0, False, False)}
    )
    # dcbf followers' speed relative to their desired velocity (optional; docs/safety.md
    # §5i): ‖v − v*‖ ≤ v_t (m/s), so the closing speed of a pair that comes into sensing
    # range is bounded at load (check (b)); 0 = off
    max_transient_speed_mps: float = field(
        default=0.0, metadata={"spec": ("float", 0.0, 100.0, False, False)}
    )
    # solver of the rcbf and dcbf QPs (optional; docs/safety.md §4b)
    qp_solver: QPSolver = field(
        default=QPSolver.DAQP, metadata={"spec": ("str", tuple(QPSolver)), "enum": QPSolver}
    )




@dataclass(frozen=True)
class LifecycleConfig:
    """``[lifecycle]`` (optional; these defaults when absent; docs/lifecycle.md): ``start``
    "airborne" (agents start at ``position``) or "ground" (``position`` is the pad, z = 0;
    take-off to ``takeoff_altitude_m`` + the vertex layer's height at ``climb_rate_mps``);
    ``land_at_s`` > 0 schedules the coordinated land-all at that mission time."""

    start: StartMode = field(
        default=StartMode.AIRBORNE, metadata={"spec": ("str", tuple(StartMode)), "enum": StartMode}
    )
    takeoff_altitude_m: float = field(
        default=2.0, metadata={"spec": ("float", 0.0, 1000.0, True, False)}
    )
    climb_rate_mps: float = field(default=1.0, metadata={"spec": ("float", 0.0, 20.0, True, False)})
    # mission time (s) of a scheduled coordinated land-all; 0 = none (gcs mission run
    # --land-at overrides it)
    land_at_s: float = field(default=0.0, metadata={"spec": ("float", 0.0, 1e6, False, False)})


# TOML section name -> its dataclass, in file order.
SECTIONS: dict[str, type] = {
    "scenario": RunConfig,
    "vehicle": VehicleConfig,
    "disturbance": DisturbanceConfig,
    "unmodeled": UnmodeledConfig,
    "formation": FormationConfig,
    "leader_trajectory": LeaderTrajectoryConfig,
    "sensing": SensingConfig,
    "communication": CommunicationConfig,
    "observer": ObserverConfig,
    "controller": ControllerConfig,
    "lifecycle": LifecycleConfig,
}
OPTIONAL_SECTIONS = ("lifecycle",)  # may be absent: their fields' defaults apply

SCHEMA: dict[str, dict[str, Spec]] = {
    section: {f.name: f.metadata["spec"] for f in fields(cls)} for section, cls in SECTIONS.items()
}

# agent ids: an in-process swarm may be this large; a distributed run gives each vehicle a
# MAVLink system id and takes 1..MAVLINK_MAX_ID only (mavlink_id_problem)
MAX_AGENT_ID = 65535
# the most agents a scenario may list: the largest swarm measured in process (a follower
# keeps rows for every agent, so memory grows with N²: 3.6 GB at 2,048; docs/performance.md)
MAX_AGENTS = 2048
# the most edges a formation graph may have: the load-time checks work edge by edge
# (a complete graph of 300 agents, 44,850 edges, loads in about 5 s), and a follower with
# hundreds of neighbours is no bearing-sensing formation (docs/graphs.md)
MAX_EDGES = 65536
MAVLINK_MAX_ID = MAX_ID  # swarm_common.ports: the MAVLink system ids the port scheme covers


def mavlink_id_problem(ids: list[int]) -> str | None:
    """One line when an agent id is outside MAVLink's system ids (1..255), else None: a
    distributed run flies each agent as its own MAVLink vehicle."""
    big = [i for i in ids if i > MAVLINK_MAX_ID]
    if not big:
        return None
    return (f"agent ids up to {max(big)}: a distributed run gives every vehicle a MAVLink "
            f"system id, 1..{MAVLINK_MAX_ID}; run a swarm this large in process (--inproc)")


AGENT_SCHEMA: dict[str, Spec] = {
    "id": ("int", 1, MAX_AGENT_ID),
    "role": ("str", tuple(Role)),
    "position": ("vec", 3, -1e4, 1e4),
    "velocity": ("vec", 3, -100.0, 100.0),
    "vertex": ("vec", 3, -1e3, 1e3),
}
# optional keys of an [[agent]] and their defaults
AGENT_OPTIONAL: dict[str, tuple[Spec, Any]] = {
    # false: a follower that flies its nominal command with no safety filter and says so
    # (its estimates carry cooperative = false): the others take the whole avoidance budget
    # against it (docs/safety.md, "A vehicle that stops cooperating")
    "cooperative": (("bool",), True),
}


def typed_value(f: Any, value: Any) -> Any:
    """A validated TOML value as the dataclass field holds it."""
    kind = f.metadata["spec"][0]
    if kind == "float":
        return float(value)
    if kind == "vec":
        return tuple(float(v) for v in value)
    if kind == "ids":
        return tuple(int(v) for v in value)
    if kind == "windows":
        return tuple((float(w[0]), float(w[1])) for w in value)
    if kind == "pairs":
        return tuple((int(w[0]), int(w[1])) for w in value)
    if kind == "str" and f.metadata["enum"] is not None:
        return f.metadata["enum"](value)
    return value


def toml_value(value: Any) -> Any:
    """A typed field value back in TOML form (lists, plain str)."""
    if isinstance(value, tuple):
        return [toml_value(v) for v in value]
    if isinstance(value, StrEnum):
        return str(value)
    return value


def describe_spec(spec: Spec) -> str:
    kind = spec[0]
    if kind == "float":
        _, lo, hi, lo_open, hi_open = spec
        return f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if kind == "int":
        return f"an integer in [{spec[1]}, {spec[2]}]"
    if kind == "str":
        # str(c): an enum member as its TOML value ('rcbf'), not <Method.RCBF: 'rcbf'>
        return "one of " + ", ".join(repr(str(c)) for c in spec[1]) if spec[1] else "a string"
    if kind == "vec":
        return f"a list of {spec[1]} numbers in [{spec[2]:g}, {spec[3]:g}]"
    if kind == "windows":
        return "a list of [start, end] pairs with 0 <= start < end"
    if kind == "ids":
        return f"a non-empty list of agent ids (integers 1..{MAX_AGENT_ID})"
    if kind == "pairs":
        return f"a list of [id, id] pairs of agent ids (integers 1..{MAX_AGENT_ID})"
    if kind == "bool":
        return "true or false"
    raise AssertionError(kind)


def check_value(value: Any, spec: Spec) -> bool:
    kind = spec[0]
    if kind == "float":
        _, lo, hi, lo_open, hi_open = spec
        if not is_finite_number(value):  # an int too large for a float too (no OverflowError)
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
            and all(is_finite_number(v) and spec[2] <= v <= spec[3] for v in value)
        )
    if kind == "windows":
        return isinstance(value, list) and all(
            isinstance(w, list)
            and len(w) == 2
            and all(is_finite_number(x) for x in w)
            and 0 <= w[0] < w[1]
            for w in value
        )
    if kind == "ids":
        return (
            isinstance(value, list)
            and len(value) > 0
            and all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= MAX_AGENT_ID
                    for v in value)
        )
    if kind == "pairs":
        return isinstance(value, list) and all(
            isinstance(w, list) and len(w) == 2 and check_value(w, ("ids",)) for w in value
        )
    if kind == "bool":
        return isinstance(value, bool)
    raise AssertionError(kind)
