"""The audit trail of a run: every command that changed a vehicle or an agent, in
``metrics.json`` under ``audit`` (docs/security.md, "Audit trail").

* ``audit.mavlink``: the simulator's records (:mod:`vehicle_sim.autopilot.audit`: time,
  vehicle, link, sender, signed, command, parameters, result), in time order;
* ``audit.zenoh``: the ground-station commands on the swarm's ``cmd/*`` keys
  (:func:`zenoh_record`: time, key, kind, agent, fields) - what the distributed runner's
  recorder heard, or the in-process runner's scripted commands;
* ``audit.counts``: per command name, the number of records per result;
* the caps and what they dropped (``mavlink_dropped``, ``zenoh_dropped``).

Both runners write the same shape (:func:`audit_document`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import asdict
from typing import Any

from swarm_common import wire

ZENOH_CAP = 5000  # Zenoh commands kept per run; later ones are only counted
MISSION_TEXT_KEEP = 200  # characters of a mission command's JSON kept in its record


def zenoh_record(t: float, key: str, cmd: wire.Command) -> dict[str, Any]:
    """One Zenoh command as an audit record: ``t`` the run's mission time (s) when it was
    seen (-1 before the first step), ``key`` its Zenoh key, and its fields (a mission's
    JSON cut to :data:`MISSION_TEXT_KEEP` characters, with its full length)."""
    fields = asdict(cmd)
    kind, agent = str(fields.pop("kind")), int(fields.pop("agent"))
    mission = str(fields.get("mission", ""))
    if len(mission) > MISSION_TEXT_KEEP:
        fields["mission"] = mission[:MISSION_TEXT_KEEP]
        fields["mission_chars"] = len(mission)
    fields["velocity"] = [float(x) for x in fields["velocity"]]
    return {"t": round(float(t), 6), "key": str(key), "kind": kind, "agent": agent,
            "fields": fields}


def counts(mavlink: list[dict[str, Any]], zenoh: list[dict[str, Any]]) -> dict[str, Any]:
    """``{command: {result: n}}`` over the MAVLink records, and ``{"zenoh:<kind>":
    {"seen": n}}`` over the Zenoh ones."""
    c: Counter[tuple[str, str]] = Counter((str(r.get("command")), str(r.get("result")))
                                          for r in mavlink)
    c.update((f"zenoh:{r.get('kind')}", "seen") for r in zenoh)
    out: dict[str, dict[str, int]] = {}
    for (name, result), n in sorted(c.items()):
        out.setdefault(name, {})[result] = n
    return out


def audit_document(
    simulator: dict[str, Any] | None, zenoh: list[dict[str, Any]], zenoh_dropped: int = 0
) -> dict[str, Any]:
    """``metrics.json``'s ``audit``: the simulator's ``--stats-out`` ``audit`` (None: no
    simulator, or one without an audit) and the Zenoh command records."""
    sim = simulator or {}
    mav = list(sim.get("records", []))
    return {
        "mavlink": mav,
        "zenoh": list(zenoh),
        "counts": counts(mav, zenoh),
        "mavlink_cap_per_vehicle": sim.get("cap_per_vehicle"),
        "mavlink_dropped": int(sim.get("dropped", 0)),
        "mavlink_dropped_per_vehicle": dict(sim.get("dropped_per_vehicle", {})),
        "zenoh_cap": ZENOH_CAP,
        "zenoh_dropped": int(zenoh_dropped),
    }
