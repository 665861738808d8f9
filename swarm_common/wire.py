"""Zenoh key expressions and payloads: defined once, here (docs/architecture.md §Zenoh).

Keys, under one root and a swarm name (``swarm/<name>/...``):

=====================================  ==========================================  ==========
key                                    payload                                     publisher
=====================================  ==========================================  ==========
``<root>/<swarm>/truth``               :class:`Truth` (all vehicles, one message;  vehicle-sim
                                       with a stored fence that changed, its
                                       outline)
``<root>/<swarm>/agent/<id>/estimate`` :class:`Estimate` (post-update, for t_k+1)  offboard
``<root>/<swarm>/agent/<id>/status``   :class:`Status`                             offboard
``<root>/<swarm>/agent/<id>/odometry`` :class:`Odometry` (own vehicle, ENU, at t_k) offboard
``<root>/<swarm>/cmd/method``          :class:`Command` kind="method"              gcs
``<root>/<swarm>/cmd/outage``          :class:`Command` kind="outage"              gcs
``<root>/<swarm>/cmd/land``            :class:`Command` kind="land"                gcs
``<root>/<swarm>/cmd/takeoff``         :class:`Command` kind="takeoff"             gcs
``<root>/<swarm>/cmd/mission``         :class:`Command` kind="mission"             gcs
``<root>/<swarm>/cmd/hold``            :class:`Command` kind="hold"                gcs
``<root>/<swarm>/cmd/live``            :class:`Command` kind="live"                gcs
=====================================  ==========================================  ==========

Payloads are msgpack maps with a version field ``"v": 1``; every float vector is
packed as little-endian float32 bytes, so both ends (and the in-process runner, which
pushes its values through the same :func:`encode` / :func:`decode`) see identical
float32-rounded numbers. A payload that fails to decode raises :class:`WireError`
(receivers count and drop it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np

from swarm_common.enums import CommandKind

VERSION = 1
DEFAULT_ROOT = "swarm"


class WireError(ValueError):
    """A payload is malformed, of another version or of another kind."""


# -- key expressions -----------------------------------------------------------------
def key_truth(swarm: str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/truth"


def key_estimate(swarm: str, agent_id: int | str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/agent/{agent_id}/estimate"


def key_status(swarm: str, agent_id: int | str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/agent/{agent_id}/status"


def key_odometry(swarm: str, agent_id: int | str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/agent/{agent_id}/odometry"


MAX_MISSION_TEXT = 1 << 18  # bytes of a command's mission JSON (1000 waypoints fit)


def _mission_text(x: Any) -> str:
    """A command's mission text, refused (WireError) unless a string of at most
    MAX_MISSION_TEXT bytes (its content is validated where it is used)."""
    if not isinstance(x, str) or len(x.encode()) > MAX_MISSION_TEXT:
        raise WireError(f"command mission: not a string of at most {MAX_MISSION_TEXT} bytes")
    return x


def _velocity(b: Any) -> tuple[float, float, float]:
    """A live command's velocity (3 float32, m/s); absent: zero. Its numbers are checked
    where they are used (finite, within the speed limit)."""
    if b is None:
        return (0.0, 0.0, 0.0)
    v = _unpack_vec(b, (3,))
    return (float(v[0]), float(v[1]), float(v[2]))


def key_cmd(swarm: str, kind: str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/cmd/{kind}"


def agent_id_from_key(key: str) -> int:
    """``.../agent/<id>/...`` -> id."""
    parts = str(key).split("/")
    try:
        return int(parts[parts.index("agent") + 1])
    except (ValueError, IndexError) as exc:
        raise WireError(f"no agent id in key {key!r}") from exc


# -- float32 helpers -----------------------------------------------------------------
def f32(a: Any) -> np.ndarray:
    """Round to float32 and return float64 (what a receiver sees)."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def _pack_vec(a: Any) -> bytes:
    return np.asarray(a, dtype="<f4").tobytes()


def _unpack_vec(b: Any, shape: tuple[int, ...]) -> np.ndarray:
    if not isinstance(b, bytes | bytearray):
        raise WireError("vector field is not bytes")
    n = 1
    for dim in shape:  # not np.prod: this runs ~10 times per message (measured 20 µs each)
        n *= dim
    if len(b) != 4 * n:
        raise WireError(f"vector field has {len(b)} bytes, expected {4 * n}")
    return np.frombuffer(b, dtype="<f4").astype(np.float64).reshape(shape)


def _qp_fields(d: dict[str, Any]) -> dict[str, Any]:
    """A status map's QP report (keys ``act``, ``qpx``) as :class:`Status` fields; none
    when the sender had none."""
    if "act" not in d:
        return {}
    n, kinds = (int(x) for x in d["act"])
    x = _unpack_vec(d["qpx"], (6,))
    return {"qp_active": n, "qp_kinds": kinds, "u_nom": x[0:3], "qp_slack": float(x[3]),
            "qp_relax": float(x[4]), "correction": float(x[5])}


def _opt_bool(d: dict[str, Any], key: str, default: bool) -> bool:
    """An optional boolean field: absent -> ``default``; anything but a bool is malformed."""
    value = d.get(key, default)
    if not isinstance(value, bool):
        raise WireError(f"field {key!r} is {type(value).__name__}, expected bool")
    return value


MAX_FENCE_COORDS = 128  # a changed fence's vertex coordinates: 64 vertices at most


def _fences(d: Any, ids: list[int]) -> dict[int, np.ndarray]:
    """A truth's changed fences (``id -> x0, y0, ...``): ids of the truth, finite pairs."""
    if not isinstance(d, dict):
        raise WireError("field 'fence' is not a map")
    out: dict[int, np.ndarray] = {}
    for name, b in d.items():
        key = int(name) if isinstance(name, str) and name.isdecimal() else -1
        if key not in ids:
            raise WireError(f"fence of {name!r}: not a vehicle of this truth")
        n = len(b) // 4 if isinstance(b, bytes) else -1
        if n % 2 or not 0 <= n <= MAX_FENCE_COORDS:
            raise WireError(f"fence of {key}: {n} coordinates")
        xy = _unpack_vec(b, (n,))
        if not np.all(np.isfinite(xy)):
            raise WireError(f"fence of {key}: not finite")
        out[key] = xy
    return out


# -- payloads ------------------------------------------------------------------------
@dataclass
class Truth:
    """Ground truth of every vehicle at control step ``step`` (time ``t``), ENU."""

    step: int
    t: float
    ids: list[int]
    p: np.ndarray  # (N,3) m
    v: np.ndarray  # (N,3) m/s
    att: np.ndarray  # (N,3) roll, pitch, yaw (ENU/FLU, rad)
    thrust: np.ndarray  # (N,) N
    lumped: np.ndarray  # (N,3) true lumped disturbance, m/s² (for metrics only)
    armed: list[bool] = field(default_factory=list)
    mode: list[str] = field(default_factory=list)
    collisions: int = 0
    # min pair distance over the physics steps of (t_k-1, t_k] (float64 on the wire)
    min_dist: float = float("inf")
    # the vehicles whose stored fence changed since the last truth: id -> its inclusion
    # polygon's ENU vertices (x0, y0, x1, y1, ...; m); empty: no single inclusion polygon
    fences: dict[int, np.ndarray] = field(default_factory=dict)


@dataclass
class Estimate:
    """An agent's post-update estimate, valid at time ``t`` (= t_k+1 for step k)."""

    id: int
    step: int
    t: float
    role: str  # "leader" | "follower"
    z1: np.ndarray  # (3,) position
    z2: np.ndarray  # (3,) velocity
    z3: np.ndarray  # (3,) lumped disturbance (zeros for leaders)
    xi: np.ndarray  # (12,) desired state [p*, ṗ*, p̈*, p⃛*]
    zeta: np.ndarray = field(default_factory=lambda: np.zeros(6))  # (6,) ζ̂
    # False while the agent's vehicle is out of OFFBOARD although the mission expects it
    # there (e.g. AUTO.LAND by a third party): z1, z2 are then its measured state and it
    # flies no safety filter, so the others avoid it alone (docs/lifecycle.md)
    cooperative: bool = True
    # the decoded float block z1..zeta are views of (None when built otherwise): one sum
    # judges all of them finite (offboard.daemon.link_guard.payload_finite); not on the wire
    block: np.ndarray | None = field(default=None, repr=False, compare=False)


@dataclass
class Status:
    """An agent's status record for the ground station (sent every control step)."""

    id: int
    step: int
    t: float
    mode: str
    method: str
    qp_status: str
    qp_solve_us: float
    h_min: float
    lyap_v: float
    est_health: str
    fallbacks: int
    u: np.ndarray = field(default_factory=lambda: np.zeros(3))
    z1: np.ndarray = field(default_factory=lambda: np.zeros(3))
    p_des: np.ndarray = field(default_factory=lambda: np.zeros(3))
    comm_ok: bool = True
    lumped: np.ndarray = field(default_factory=lambda: np.zeros(3))  # z3 + Φζ̂ used, m/s²
    input_clipped: bool = False  # the setpoint conversion changed the commanded u this step
    alarms: int = 0  # enums.AgentAlarm bits the agent raised this step (docs/safety.md)
    # the safety QP's rows active at its solution (count, enums.QPRow bits), the CLF slack
    # δ and the relaxation σ (m/s²), the nominal control and the correction ‖u_f − u_nom‖
    # (m/s²; offboard.records.AgentStatus); absent on the wire from older senders: 0
    qp_active: int = 0
    qp_kinds: int = 0
    qp_slack: float = 0.0
    qp_relax: float = 0.0
    u_nom: np.ndarray = field(default_factory=lambda: np.zeros(3))
    correction: float = 0.0


@dataclass
class Odometry:
    """One vehicle's own measured state at control step ``step`` (time ``t`` = t_k), ENU,
    from the ODOMETRY its autopilot sends (converted once, in :mod:`swarm_common.frames`);
    published by that vehicle's daemon, read by the others' ``--sensing odometry``."""

    id: int
    step: int
    t: float
    p: np.ndarray  # (3,) m
    v: np.ndarray  # (3,) m/s


# Command.kind (swarm_common.enums.CommandKind); others fail decode
COMMAND_KINDS = tuple(k.value for k in CommandKind)


@dataclass
class Command:
    """A ground-station command to the swarm: ``kind`` = "method", "outage", "land"
    (coordinated land-all, docs/lifecycle.md: every agent starts its landing reference at
    mission time ``at_s``) or "takeoff" (coordinated take-off of a ground start held on its
    pads: the climbs start at mission time ``at_s``), "mission" (the leaders fly the
    formation waypoints of ``mission``, a ``[mission]`` table as JSON text, from the first
    rest at or after ``at_s``; docs/missions.md) or "hold" (the formation stops at its next
    rest after ``at_s``), or "live" (the formation's centroid flies at ``velocity`` (m/s,
    ENU) from ``at_s`` for a short while, then brakes to rest unless a newer one follows;
    docs/missions.md, "Flying the formation live"); a negative ``at_s`` means at the step
    the command arrives."""

    kind: str
    agent: int = 0  # 0 = all
    method: str = ""
    duration_s: float = 0.0
    at_s: float = -1.0
    mission: str = ""  # kind "mission": the [mission] table as JSON (MAX_MISSION_TEXT bytes)
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)  # kind "live": m/s, ENU


Payload = Truth | Estimate | Status | Command | Odometry


def encode(obj: Payload) -> bytes:
    """Payload -> bytes (msgpack map, float32 vectors)."""
    if isinstance(obj, Truth):
        n = len(obj.ids)
        d: dict[str, Any] = {
            "v": VERSION,
            "k": "truth",
            "step": int(obj.step),
            "t": float(obj.t),
            "ids": [int(i) for i in obj.ids],
            "p": _pack_vec(np.reshape(obj.p, (n, 3))),
            "vel": _pack_vec(np.reshape(obj.v, (n, 3))),
            "att": _pack_vec(np.reshape(obj.att, (n, 3))),
            "F": _pack_vec(np.reshape(obj.thrust, (n,))),
            "lump": _pack_vec(np.reshape(obj.lumped, (n, 3))),
            "armed": [bool(a) for a in obj.armed],
            "mode": [str(m) for m in obj.mode],
            "coll": int(obj.collisions),
            "md": float(obj.min_dist),
        }
        if obj.fences:  # only on the steps where a stored fence changed
            d["fence"] = {str(int(i)): _pack_vec(np.ravel(xy)) for i, xy in obj.fences.items()}
    elif isinstance(obj, Estimate):
        d = {
            "v": VERSION,
            "k": "est",
            "id": int(obj.id),
            "step": int(obj.step),
            "t": float(obj.t),
            "role": obj.role,
            # z1 | z2 | z3 | xi | zeta: one float32 block (27 values), one unpack per message
            "x": _pack_vec(np.concatenate([
                np.ravel(obj.z1), np.ravel(obj.z2), np.ravel(obj.z3), np.ravel(obj.xi),
                np.ravel(obj.zeta),
            ])),
        }
        if not obj.cooperative:  # absent = True: older receivers and senders agree
            d["coop"] = False
    elif isinstance(obj, Status):
        d = {
            "v": VERSION,
            "k": "status",
            "id": int(obj.id),
            "step": int(obj.step),
            "t": float(obj.t),
            "mode": obj.mode,
            "method": obj.method,
            "qp": obj.qp_status,
            "qp_us": float(obj.qp_solve_us),
            "h_min": float(obj.h_min),
            "V": float(obj.lyap_v),
            "est": obj.est_health,
            "fb": int(obj.fallbacks),
            "u": _pack_vec(obj.u),
            "z1": _pack_vec(obj.z1),
            "p_des": _pack_vec(obj.p_des),
            "comm": bool(obj.comm_ok),
            "lump": _pack_vec(obj.lumped),
            "clip": bool(obj.input_clipped),
            "alarm": int(obj.alarms),
            "act": [int(obj.qp_active), int(obj.qp_kinds)],
            # u_nom | δ, σ, correction: one float32 block
            "qpx": _pack_vec(np.concatenate([np.ravel(obj.u_nom), [
                obj.qp_slack, obj.qp_relax, obj.correction]])),
        }
    elif isinstance(obj, Odometry):
        d = {
            "v": VERSION,
            "k": "odo",
            "id": int(obj.id),
            "step": int(obj.step),
            "t": float(obj.t),
            "x": _pack_vec(np.concatenate([np.ravel(obj.p), np.ravel(obj.v)])),
        }
    elif isinstance(obj, Command):
        d = {
            "v": VERSION,
            "k": "cmd",
            "kind": obj.kind,
            "agent": int(obj.agent),
            "method": obj.method,
            "dur": float(obj.duration_s),
            "at": float(obj.at_s),
        }
        if obj.mission:
            d["mis"] = obj.mission
        if obj.kind == "live":
            d["vel"] = _pack_vec(np.asarray(obj.velocity, dtype=float).reshape(3))
    else:
        raise TypeError(f"cannot encode {type(obj).__name__}")
    return msgpack.packb(d, use_bin_type=True)


def decode(data: bytes | bytearray | memoryview) -> Payload:
    """Bytes -> payload. Raises :class:`WireError` on anything malformed."""
    try:
        d = msgpack.unpackb(bytes(data), raw=False)
    except (ValueError, TypeError) as exc:
        # msgpack's malformed-input errors are ValueErrors; unhashable map keys TypeError
        raise WireError(f"not msgpack: {exc}") from None
    if not isinstance(d, dict):
        raise WireError("payload is not a map")
    if d.get("v") != VERSION:
        raise WireError(f"payload version {d.get('v')!r}, expected {VERSION}")
    try:
        kind = d["k"]
        if kind == "truth":
            ids = [int(i) for i in d["ids"]]
            n = len(ids)
            return Truth(
                step=int(d["step"]),
                t=float(d["t"]),
                ids=ids,
                p=_unpack_vec(d["p"], (n, 3)),
                v=_unpack_vec(d["vel"], (n, 3)),
                att=_unpack_vec(d["att"], (n, 3)),
                thrust=_unpack_vec(d["F"], (n,)),
                lumped=_unpack_vec(d["lump"], (n, 3)),
                armed=[bool(a) for a in d["armed"]],
                mode=[str(m) for m in d["mode"]],
                collisions=int(d["coll"]),
                min_dist=float(d.get("md", float("inf"))),
                fences=_fences(d.get("fence", {}), ids),
            )
        if kind == "est":
            x = _unpack_vec(d["x"], (27,))
            return Estimate(
                id=int(d["id"]),
                step=int(d["step"]),
                t=float(d["t"]),
                role=str(d["role"]),
                z1=x[0:3],
                z2=x[3:6],
                z3=x[6:9],
                xi=x[9:21],
                zeta=x[21:27],
                cooperative=_opt_bool(d, "coop", True),
                block=x,
            )
        if kind == "status":
            return Status(
                id=int(d["id"]),
                step=int(d["step"]),
                t=float(d["t"]),
                mode=str(d["mode"]),
                method=str(d["method"]),
                qp_status=str(d["qp"]),
                qp_solve_us=float(d["qp_us"]),
                h_min=float(d["h_min"]),
                lyap_v=float(d["V"]),
                est_health=str(d["est"]),
                fallbacks=int(d["fb"]),
                u=_unpack_vec(d["u"], (3,)),
                z1=_unpack_vec(d["z1"], (3,)),
                p_des=_unpack_vec(d["p_des"], (3,)),
                comm_ok=bool(d["comm"]),
                lumped=_unpack_vec(d["lump"], (3,)) if "lump" in d else np.zeros(3),
                input_clipped=bool(d.get("clip", False)),
                alarms=int(d.get("alarm", 0)),
                **_qp_fields(d),
            )
        if kind == "odo":
            x = _unpack_vec(d["x"], (6,))
            return Odometry(id=int(d["id"]), step=int(d["step"]), t=float(d["t"]),
                            p=x[0:3], v=x[3:6])
        if kind == "cmd":
            if d["kind"] not in COMMAND_KINDS:
                raise WireError(f"unknown command kind {d['kind']!r}")
            return Command(
                kind=str(d["kind"]),
                agent=int(d["agent"]),
                method=str(d["method"]),
                duration_s=float(d["dur"]),
                at_s=float(d.get("at", -1.0)),
                mission=_mission_text(d.get("mis", "")),
                velocity=_velocity(d.get("vel")),
            )
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, WireError):
            raise
        raise WireError(f"bad field: {exc!r}") from None
    raise WireError(f"unknown payload kind {d.get('k')!r}")


def roundtrip(obj: Payload) -> Payload:
    """encode + decode: what a receiver would see (used by the in-process runner)."""
    return decode(encode(obj))
