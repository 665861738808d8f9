"""The payloads (dataclasses) and their encoding: msgpack maps with a version field, every
float vector little-endian float32 bytes (:mod:`swarm_common.wire`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np

from swarm_common.enums import CommandKind

VERSION = 1
MAX_MISSION_TEXT = 1 << 18  # bytes of a command's mission JSON (1000 waypoints fit)
MAX_FENCE_COORDS = 128  # a changed fence's vertex coordinates: 64 vertices at most


class WireError(ValueError):
    """A payload is malformed, of another version or of another kind."""



# -- float32 helpers -----------------------------------------------------------------
def f32(a: Any) -> np.ndarray:
    """Round to float32 and return float64 (what a receiver sees)."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def _pack_vec(a: Any) -> bytes:
    return np.asarray(a, dtype="<f4").tobytes()


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
