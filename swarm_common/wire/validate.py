"""Bytes to payloads: :func:`decode` checks every field of an untrusted payload (its
version, kind, types, vector sizes and bounds) and raises
:class:`~swarm_common.wire.payloads.WireError` on anything malformed."""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

from swarm_common.wire import payloads as pl
from swarm_common.wire.payloads import Payload, WireError


def _unpack_vec(b: Any, shape: tuple[int, ...]) -> np.ndarray:
    if not isinstance(b, bytes | bytearray):
        raise WireError("vector field is not bytes")
    n = 1
    for dim in shape:  # not np.prod: this runs ~10 times per message (measured 20 µs each)
        n *= dim
    if len(b) != 4 * n:
        raise WireError(f"vector field has {len(b)} bytes, expected {4 * n}")
    return np.frombuffer(b, dtype="<f4").astype(np.float64).reshape(shape)



def _mission_text(x: Any) -> str:
    """A command's mission text, refused (WireError) unless a string of at most
    MAX_MISSION_TEXT bytes (its content is validated where it is used)."""
    if not isinstance(x, str) or len(x.encode()) > pl.MAX_MISSION_TEXT:
        raise WireError(f"command mission: not a string of at most {pl.MAX_MISSION_TEXT} bytes")
    return x


def _velocity(b: Any) -> tuple[float, float, float]:
    """A live command's velocity (3 float32, m/s); absent: zero. Its numbers are checked
    where they are used (finite, within the speed limit)."""
    if b is None:
        return (0.0, 0.0, 0.0)
    v = _unpack_vec(b, (3,))
    return (float(v[0]), float(v[1]), float(v[2]))


def _qp_fields(d: dict[str, Any]) -> dict[str, Any]:
    """A status map's QP report (keys ``act``, ``qpx``) as the fields of a
    :class:`~swarm_common.wire.payloads.Status`; none when the sender had none."""
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
        if n % 2 or not 0 <= n <= pl.MAX_FENCE_COORDS:
            raise WireError(f"fence of {key}: {n} coordinates")
        xy = _unpack_vec(b, (n,))
        if not np.all(np.isfinite(xy)):
            raise WireError(f"fence of {key}: not finite")
        out[key] = xy
    return out


def decode(data: bytes | bytearray | memoryview) -> Payload:
    """Bytes -> payload. Raises :class:`WireError` on anything malformed."""
    try:
        d = msgpack.unpackb(bytes(data), raw=False)
    except (ValueError, TypeError) as exc:
        # msgpack's malformed-input errors are ValueErrors; unhashable map keys TypeError
        raise WireError(f"not msgpack: {exc}") from None
    if not isinstance(d, dict):
        raise WireError("payload is not a map")
    if d.get("v") != pl.VERSION:
        raise WireError(f"payload version {d.get('v')!r}, expected {pl.VERSION}")
    try:
        kind = d["k"]
        if kind == "truth":
            ids = [int(i) for i in d["ids"]]
            n = len(ids)
            return pl.Truth(
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
            return pl.Estimate(
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
            return pl.Status(
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
            return pl.Odometry(id=int(d["id"]), step=int(d["step"]), t=float(d["t"]),
                            p=x[0:3], v=x[3:6])
        if kind == "cmd":
            if d["kind"] not in pl.COMMAND_KINDS:
                raise WireError(f"unknown command kind {d['kind']!r}")
            return pl.Command(
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
    return decode(pl.encode(obj))
