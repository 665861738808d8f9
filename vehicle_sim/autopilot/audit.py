"""The audit trail of a simulated vehicle: one record per command-like message that may
change it (docs/security.md, "Audit trail").

Recorded: COMMAND_LONG / COMMAND_INT of any kind, SET_MODE, PARAM_SET, the end of a
mission/fence/rally upload (its final MISSION_ACK), MISSION_CLEAR_ALL and
MISSION_SET_CURRENT; never setpoints or telemetry (the hot path stays as it was). Each
record (:func:`record`) is a JSON-ready dict::

    {"t": sim s, "vehicle": id, "link": "api" | "gcs" | ..., "peer": "host:port",
     "sysid": ..., "compid": ..., "signed": bool, "restricted": bool,
     "command": "MAV_CMD_..." | "SET_MODE" | "PARAM_SET" | "MISSION_UPLOAD" | ...,
     "params": [...], "result": "MAV_RESULT_..." | ..., "accepted": bool, "reason": str}

``restricted``: an unsigned frame let through on a signed link that admits unsigned
read-only peers (``_restricted``, :mod:`vehicle_sim.link.endpoint`). A vehicle keeps the
first :data:`AUDIT_CAP` records and counts the rest (``dropped``), so a flood of
commands costs bounded memory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as M

AUDIT_CAP = 5000  # records kept per vehicle; later ones are only counted


def enum_name(enum: str, value: int) -> str:
    """``value``'s name in pymavlink's enum ``enum`` (e.g. ``MAV_RESULT_ACCEPTED``), or
    ``"<enum> <value>"`` for a value the dialect does not name."""
    entry = M.enums.get(enum, {}).get(int(value))
    return entry.name if entry is not None else f"{enum} {int(value)}"


def json_number(x: Any) -> float | str | None:
    """A parameter as a JSON value: a string as it is (PARAM_SET's name), a number as a
    float, None for NaN/inf or anything else (MAVSDK sends NaN for unused parameters)."""
    if isinstance(x, str):
        return x
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return None
    return xf if math.isfinite(xf) else None


@dataclass
class AuditLog:
    """One vehicle's bounded audit list: the first ``cap`` records, then a count."""

    cap: int = AUDIT_CAP
    records: list[dict[str, Any]] = field(default_factory=list)
    dropped: int = 0

    def add(self, rec: dict[str, Any]) -> None:
        if len(self.records) < self.cap:
            self.records.append(rec)
        else:
            self.dropped += 1

    def as_dict(self) -> dict[str, Any]:
        return {"records": list(self.records), "dropped": self.dropped, "cap": self.cap}


def _peer(src: Any) -> tuple[str, str]:
    """(link name, "host:port") of a ``Dest`` = (link name, address)."""
    if isinstance(src, tuple) and len(src) == 2:
        link, addr = src
        if isinstance(addr, tuple) and len(addr) == 2:
            return str(link), f"{addr[0]}:{addr[1]}"
        return str(link), ""
    return "", ""


def _sender(m: Any, attr: str) -> int:
    get = getattr(m, attr, None)
    try:
        return int(get()) if get is not None else 0
    except (TypeError, ValueError):
        return 0


def record(
    v: Any, m: Any, src: Any, sim_t: float, command: str, params: list[Any],
    result: str, accepted: bool, reason: str = "",
) -> None:
    """Append one record to ``v.audit`` (an :class:`AuditLog`; nothing when the vehicle
    has none). ``m``: the received message (sender ids, signature, ``_restricted``);
    ``src``: (link name, address); ``sim_t``: simulation time (s)."""
    log: AuditLog | None = getattr(v, "audit", None)
    if log is None:
        return
    if len(log.records) >= log.cap:  # past the cap: count only, build nothing
        log.dropped += 1
        return
    link, peer = _peer(src)
    signed = getattr(m, "get_signed", None)
    log.add({
        "t": round(float(sim_t), 6), "vehicle": int(v.id), "link": link, "peer": peer,
        "sysid": _sender(m, "get_srcSystem"), "compid": _sender(m, "get_srcComponent"),
        "signed": bool(signed()) if signed is not None else False,
        "restricted": bool(getattr(m, "_restricted", False)),
        "command": command, "params": [json_number(p) for p in params],
        "result": result, "accepted": bool(accepted), "reason": reason,
    })  # fmt: skip


def record_command(
    v: Any, m: Any, src: Any, sim_t: float, cmd: int, params: tuple[float, ...],
    result: int, reason: str = "",
) -> None:
    """A COMMAND_LONG / COMMAND_INT (``cmd`` a MAV_CMD) answered with MAV_RESULT ``result``."""
    record(v, m, src, sim_t, enum_name("MAV_CMD", cmd), list(params),
           enum_name("MAV_RESULT", result), result == M.MAV_RESULT_ACCEPTED, reason)


def record_mission_acks(
    v: Any, m: Any, src: Any, sim_t: float, command: str, outs: list[tuple[Any, Any]]
) -> None:
    """The MISSION_ACKs among ``outs`` (what a mission handler queued for ``m``): one
    record each, ``command`` with the mission type as its parameter (an upload's final
    ACK, or a clear's)."""
    for msg, _dest in outs:
        if msg.get_msgId() == M.MAVLINK_MSG_ID_MISSION_ACK:
            record(v, m, src, sim_t, command, [int(msg.mission_type)],
                   enum_name("MAV_MISSION_RESULT", msg.type),
                   msg.type == M.MAV_MISSION_ACCEPTED)


def stats_document(logs: list[tuple[int, AuditLog]]) -> dict[str, Any]:
    """The ``audit`` of ``--stats-out``: every vehicle's records in time order, the cap
    per vehicle and the records dropped past it (total and per vehicle id)."""
    recs = [r for _, log in logs for r in log.records]
    recs.sort(key=lambda r: (r["t"], r["vehicle"]))
    per = {str(vid): log.dropped for vid, log in logs if log.dropped}
    return {"cap_per_vehicle": logs[0][1].cap if logs else AUDIT_CAP, "records": recs,
            "dropped": sum(per.values()), "dropped_per_vehicle": per}
