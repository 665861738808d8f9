"""The ``[mission]`` table of a scenario: validation, typed view and the way back to TOML.

A mission is a list of formation waypoints (centroid m ENU, scale, yaw deg, hold s) flown at a
cruise speed (m/s, the centroid's peak speed on a leg) under per-agent speed (m/s),
acceleration (m/s^2) and jerk (m/s^3) limits. Every refusal is one :class:`MissionError` line
naming the key and what is allowed, e.g.::

    mission.waypoint[3].scale = nan: must be a number in (0, 10]

The numeric checks are :mod:`swarm_common.table_check`'s, shared with the world's tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from swarm_common.table_check import Range as _Range
from swarm_common.table_check import check_keys, describe, number, show, vector

__all__ = [
    "MAX_WAYPOINTS",
    "MissionConfig",
    "MissionError",
    "Waypoint",
    "mission_toml",
    "parse_mission",
]

MAX_WAYPOINTS = 1000

# key -> (lo, hi, lo_open, hi_open, default or None when required)
_MISSION_KEYS: dict[str, tuple[_Range, float | None]] = {
    "speed_mps": ((0.0, 15.0, True, False), None),
    "start_s": ((0.0, 3600.0, False, False), 0.0),
    "max_speed_mps": ((0.0, 15.0, True, False), 5.0),
    "max_accel_mps2": ((0.0, 20.0, True, False), 1.5),
    "max_jerk_mps3": ((0.0, 100.0, True, False), 3.0),
    "arrive_radius_m": ((0.0, 100.0, True, False), 0.5),
}
_MISSION_ALLOWED = (*_MISSION_KEYS, "waypoint")
_CENTROID_RANGE: _Range = (-1e4, 1e4, False, False)
_WAYPOINT_KEYS: dict[str, tuple[_Range, float | None]] = {
    "scale": ((0.0, 10.0, True, False), 1.0),
    "yaw_deg": ((-720.0, 720.0, False, False), 0.0),
    "hold_s": ((0.0, 3600.0, False, False), 0.0),
    "speed_mps": ((0.0, 15.0, True, False), None),  # optional, no default (mission's)
}
_WAYPOINT_ALLOWED = ("centroid", *_WAYPOINT_KEYS)


class MissionError(ValueError):
    """A ``[mission]`` table (or a plan built from it) that cannot be flown; one line."""


@dataclass(frozen=True)
class Waypoint:
    """One formation waypoint: centroid (m, ENU), scale (1 = the scenario's shape), yaw (deg,
    about +z, absolute: the leg turns by the difference, not the shortest way), hold (s) at
    the waypoint after arriving, and the cruise speed (m/s) of the leg arriving here (None:
    the mission's)."""

    centroid: tuple[float, float, float]
    scale: float = 1.0
    yaw_deg: float = 0.0
    hold_s: float = 0.0
    speed_mps: float | None = None


@dataclass(frozen=True)
class MissionConfig:
    """The validated ``[mission]`` table. ``speed_mps``: cruise (peak) speed of the centroid
    (m/s); ``start_s``: when the first leg leaves the initial pose (s); ``max_*``: no agent
    faster / harder / jerkier than this (m/s, m/s^2, m/s^3); ``arrive_radius_m``: how close
    (m) counts as arrived."""

    waypoints: tuple[Waypoint, ...]
    speed_mps: float
    start_s: float = 0.0
    max_speed_mps: float = 5.0
    max_accel_mps2: float = 1.5
    max_jerk_mps3: float = 3.0
    arrive_radius_m: float = 0.5


def _number(value: object, where: str, rng: _Range) -> float:
    return number(value, where, rng, MissionError)


def _vector3(value: object, where: str, rng: _Range) -> tuple[float, float, float]:
    a, b, c = vector(value, where, 3, rng, MissionError)
    return (a, b, c)


def _check_keys(table: dict[Any, Any], where: str, allowed: tuple[str, ...]) -> None:
    check_keys(table, where, allowed, MissionError)


def _waypoint(raw: object, k: int, max_speed: float) -> Waypoint:
    where = f"mission.waypoint[{k}]"
    if not isinstance(raw, dict):
        raise MissionError(f"{where} = {show(raw)}: must be a table")
    _check_keys(raw, where, _WAYPOINT_ALLOWED)
    if "centroid" not in raw:
        raise MissionError(
            f"missing key {where}.centroid (a list of 3 numbers in [-10000, 10000], m)"
        )
    centroid = _vector3(raw["centroid"], f"{where}.centroid", _CENTROID_RANGE)
    vals: dict[str, float | None] = {}
    for key, (rng, default) in _WAYPOINT_KEYS.items():
        vals[key] = _number(raw[key], f"{where}.{key}", rng) if key in raw else default
    speed = vals["speed_mps"]
    if speed is not None and speed > max_speed:
        raise MissionError(
            f"{where}.speed_mps = {speed:g}: must not exceed mission.max_speed_mps = {max_speed:g}"
        )
    return Waypoint(
        centroid=centroid,
        scale=float(vals["scale"] or 0.0),  # never None: each has a default
        yaw_deg=float(vals["yaw_deg"] or 0.0),
        hold_s=float(vals["hold_s"] or 0.0),
        speed_mps=speed,
    )


def parse_mission(table: object) -> MissionConfig:
    """Validate a decoded ``[mission]`` TOML table (the value under ``mission``).

    Raises :class:`MissionError` (one line naming the key) on: not a table, unknown keys,
    a missing ``speed_mps`` / ``waypoint`` / ``centroid``, no or more than
    :data:`MAX_WAYPOINTS` waypoints, non-numbers (bools included), NaN / inf, ints too large
    for a float, a wrong vector length, out-of-range values, and a cruise speed (mission's or
    a waypoint's) above ``max_speed_mps``."""
    if not isinstance(table, dict):
        raise MissionError(f"[mission] = {show(table)}: must be a table")
    _check_keys(table, "mission", _MISSION_ALLOWED)
    vals: dict[str, float] = {}
    for key, (rng, default) in _MISSION_KEYS.items():
        if key in table:
            vals[key] = _number(table[key], f"mission.{key}", rng)
        elif default is None:
            raise MissionError(f"missing key mission.{key} ({describe(rng)})")
        else:
            vals[key] = default
    if vals["speed_mps"] > vals["max_speed_mps"]:
        raise MissionError(
            f"mission.speed_mps = {vals['speed_mps']:g}: must not exceed "
            f"mission.max_speed_mps = {vals['max_speed_mps']:g}"
        )
    if "waypoint" not in table:
        raise MissionError(
            f"missing key mission.waypoint (1 to {MAX_WAYPOINTS} [[mission.waypoint]] tables)"
        )
    raw = table["waypoint"]
    if not isinstance(raw, list):
        raise MissionError(
            f"mission.waypoint = {show(raw)}: must be a list of [[mission.waypoint]] tables"
        )
    if not raw:
        raise MissionError("mission.waypoint = []: must list at least 1 waypoint")
    if len(raw) > MAX_WAYPOINTS:
        raise MissionError(
            f"mission.waypoint: {len(raw)} waypoints; at most {MAX_WAYPOINTS} allowed"
        )
    waypoints = tuple(_waypoint(w, k, vals["max_speed_mps"]) for k, w in enumerate(raw))
    return MissionConfig(waypoints=waypoints, **vals)


def mission_toml(cfg: MissionConfig) -> dict[str, Any]:
    """``cfg`` as a TOML-ready ``[mission]`` table (``parse_mission`` gives ``cfg`` back)."""
    out: dict[str, Any] = {key: float(getattr(cfg, key)) for key in _MISSION_KEYS}
    wps: list[dict[str, Any]] = []
    for w in cfg.waypoints:
        row: dict[str, Any] = {
            "centroid": [float(x) for x in w.centroid],
            "scale": float(w.scale),
            "yaw_deg": float(w.yaw_deg),
            "hold_s": float(w.hold_s),
        }
        if w.speed_mps is not None:
            row["speed_mps"] = float(w.speed_mps)
        wps.append(row)
    out["waypoint"] = wps
    return out
