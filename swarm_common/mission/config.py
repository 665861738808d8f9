"""The ``[mission]`` table of a scenario: validation, typed view and the way back to TOML.

A mission is a list of formation waypoints (centroid m ENU, scale, yaw deg, hold s) flown at a
cruise speed (m/s, the centroid's peak speed on a leg) under per-agent speed (m/s),
acceleration (m/s^2) and jerk (m/s^3) limits. Every refusal is one :class:`MissionError` line
naming the key and what is allowed, e.g.::

    mission.waypoint[3].scale = nan: must be a number in (0, 10]

The numeric checks are written here rather than borrowed from
:mod:`swarm_common.scenario.schema` so that the scenario loader may import this module
without a cycle between the two rooms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

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
_Range = tuple[float, float, bool, bool]
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


def _show(value: object, limit: int = 40) -> str:
    """``repr`` of a value, cut to ``limit`` characters (always one line)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _key(key: object) -> str:
    """A table key as it may appear in a message: plain names as they are, others quoted."""
    if isinstance(key, str) and key.replace("_", "a").isalnum() and key.isascii():
        return key
    return _show(str(key) if not isinstance(key, str) else key, 30)


def _describe(rng: _Range) -> str:
    lo, hi, lo_open, hi_open = rng
    return f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def _as_float(value: object) -> float | None:
    """``value`` as a finite float, or None (bools, non-numbers, NaN, inf, huge ints)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        out = float(value)
    except OverflowError:
        return None
    return out if math.isfinite(out) else None


def _in_range(x: float, rng: _Range) -> bool:
    lo, hi, lo_open, hi_open = rng
    return (x > lo if lo_open else x >= lo) and (x < hi if hi_open else x <= hi)


def _number(value: object, where: str, rng: _Range) -> float:
    x = _as_float(value)
    if x is None or not _in_range(x, rng):
        raise MissionError(f"{where} = {_show(value)}: must be {_describe(rng)}")
    return x


def _vector3(value: object, where: str, rng: _Range) -> tuple[float, float, float]:
    lo, hi, _, _ = rng
    rule = f"a list of 3 numbers in [{lo:g}, {hi:g}]"
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise MissionError(f"{where} = {_show(value)}: must be {rule}")
    xs = [_as_float(v) for v in value]
    if any(x is None or not _in_range(x, rng) for x in xs):
        raise MissionError(f"{where} = {_show(value)}: must be {rule}")
    a, b, c = (float(x) for x in xs if x is not None)
    return (a, b, c)


def _check_keys(table: dict[Any, Any], where: str, allowed: tuple[str, ...]) -> None:
    for key in table:
        if key not in allowed:
            raise MissionError(f"unknown key {where}.{_key(key)}; allowed: {', '.join(allowed)}")


def _waypoint(raw: object, k: int, max_speed: float) -> Waypoint:
    where = f"mission.waypoint[{k}]"
    if not isinstance(raw, dict):
        raise MissionError(f"{where} = {_show(raw)}: must be a table")
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
        raise MissionError(f"[mission] = {_show(table)}: must be a table")
    _check_keys(table, "mission", _MISSION_ALLOWED)
    vals: dict[str, float] = {}
    for key, (rng, default) in _MISSION_KEYS.items():
        if key in table:
            vals[key] = _number(table[key], f"mission.{key}", rng)
        elif default is None:
            raise MissionError(f"missing key mission.{key} ({_describe(rng)})")
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
            f"mission.waypoint = {_show(raw)}: must be a list of [[mission.waypoint]] tables"
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
