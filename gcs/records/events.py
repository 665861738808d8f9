"""The ``/events`` of a record (foxglove.Log, docs/records.md): what a run's documents say
happened, on the sim clock. No I/O.

From ``metrics.json``: the start (scenario, method, seed), each ``safety_alarms`` entry,
the commands of its ``audit`` (each vehicle's MAVLink commands with their results: the
modes asked for, arming, ...; the ground station's Zenoh commands: :func:`audit_events`),
the faults and failsafes of a distributed run (``run``: agents killed on purpose, agents
that failed, the simulator's offboard-loss failsafes) and the end (verdict).
From the series: each agent's QP falling back and recovering (``fallback``), the onsets of
its :class:`~swarm_common.enums.AgentAlarm` bits and of input clipping.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_common.enums import AgentAlarm
from swarm_common.px4 import custom_mode, short_name

MAX_EVENTS = 10_000  # a record's /events stop there (a chattering run stays readable)
DEBUG, INFO, WARNING, ERROR = 1, 2, 3, 4  # foxglove.LogLevel values


@dataclass(frozen=True)
class Event:
    """One ``foxglove.Log``: ``ns`` sim time (ns), ``level`` (foxglove.LogLevel value),
    ``name`` (the source: ``run``, ``safety``, ``agent/<id>``) and the text."""

    ns: int
    level: int
    name: str
    message: str


def _onsets(cond: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(steps, columns) where ``cond`` (K, N) becomes True (True at step 0 counts)."""
    prev = np.zeros((1, cond.shape[1]), bool)
    rise = cond & ~np.concatenate([prev, cond[:-1]])
    steps, cols = np.nonzero(rise)
    return steps, cols


def series_events(ns: np.ndarray, ids: Sequence[int], fallback: np.ndarray,
                  alarms: np.ndarray, clipped: np.ndarray) -> list[Event]:
    """Onsets of each agent's QP fallback (and its recovery), alarm bits and clipping;
    ``ns`` (K,) sim time (ns), the others (K, N)."""
    out = []
    fb = np.asarray(fallback, bool)
    for k, a in zip(*_onsets(fb), strict=True):
        out.append(Event(int(ns[k]), WARNING, f"agent/{ids[a]}", "QP degraded: fallback"))
    for k, a in zip(*np.nonzero(fb[:-1] & ~fb[1:]), strict=True):  # falling edges
        out.append(Event(int(ns[k + 1]), INFO, f"agent/{ids[a]}", "QP recovered"))
    al = np.asarray(alarms).astype(np.int64)
    for bit in AgentAlarm:
        for k, a in zip(*_onsets((al & int(bit)) != 0), strict=True):
            out.append(Event(int(ns[k]), WARNING, f"agent/{ids[a]}",
                             f"alarm {bit.name}"))
    for k, a in zip(*_onsets(np.asarray(clipped, bool)), strict=True):
        out.append(Event(int(ns[k]), DEBUG, f"agent/{ids[a]}", "input clipped (tilt/thrust)"))
    return out


def start_event(doc: Mapping[str, Any], ns0: int) -> Event:
    """The start of the run at ``ns0``: its scenario, method and seed (``doc``'s keys)."""
    return Event(ns0, INFO, "run", f"start: scenario {doc.get('scenario')}, method "
                 f"{doc.get('method')}, seed {doc.get('seed')}")


def run_failed_event(why: str, ns: int) -> Event:
    """A run that stopped at ``ns`` without its document: ``why``, its one-line error."""
    return Event(ns, ERROR, "run", f"failed: {why}")


def document_events(doc: Mapping[str, Any], ns0: int, ns1: int) -> list[Event]:
    """The start and end of the run (at ``ns0`` and ``ns1``) and the events listed in its
    ``metrics.json`` document."""
    m = doc.get("metrics") or {}
    out = [start_event(doc, ns0)]
    for e in m.get("safety_alarms") or []:
        if not isinstance(e, Mapping):
            continue
        kind = str(e.get("assumption"))
        lvl = ERROR if kind in ("collision", "ground_strike") else WARNING
        t = e.get("t_s")
        at = ns0 if not isinstance(t, int | float) else int(round(float(t) * 1e9))
        out.append(Event(at, lvl, "safety", f"{kind}: agent {e.get('agent')}, other "
                         f"{e.get('other')}, value {e.get('value')}"))
    out += audit_events(doc, ns0, ns1)
    run = doc.get("run")
    run = run if isinstance(run, Mapping) else {}
    if run.get("killed_agents"):
        out.append(Event(ns1, WARNING, "run", f"fault: agents killed on purpose: "
                         f"{run['killed_agents']}"))
    failed = run.get("failed_agents")
    if failed:
        out.append(Event(ns1, ERROR, "run", f"failed agents: {failed}"))
    sim = run.get("simulator")
    summary = str(sim.get("summary", "")) if isinstance(sim, Mapping) else ""
    failsafes = re.search(r"\bfailsafes=(\d+)", summary)
    if failsafes and int(failsafes.group(1)) > 0:
        out.append(Event(ns1, WARNING, "run", f"vehicle-sim: {failsafes.group(1)} "
                         "offboard-loss failsafes"))
    if doc.get("aborted"):
        out.append(Event(ns1, ERROR, "run", "aborted"))
    out.append(Event(ns1, INFO, "run", f"end: safety verdict {m.get('safety_verdict')}, "
                     f"min distance {m.get('min_distance_m')} m"))
    return out


# MAVLink commands that only configure telemetry: DEBUG when accepted
_TELEMETRY_COMMANDS = ("MAV_CMD_REQUEST_MESSAGE", "MAV_CMD_SET_MESSAGE_INTERVAL",
                       "MAV_CMD_REQUEST_DATA_STREAM")


def _at(t: Any, ns0: int, ns1: int) -> int:
    """An audit record's time ``t`` (s) in ns, within the run's [``ns0``, ``ns1``] (a
    command before the first step or after the last is shown there); ``ns0`` when absent."""
    if not isinstance(t, int | float) or not math.isfinite(t):
        return ns0
    return min(max(int(round(float(t) * 1e9)), ns0), ns1)


def _number(params: Any, i: int) -> float | None:
    x = params[i] if isinstance(params, list) and len(params) > i else None
    return float(x) if isinstance(x, int | float) else None


def mavlink_text(command: str, params: Any) -> str:
    """A MAVLink audit record's command in words: the mode a DO_SET_MODE or SET_MODE
    asks for (PX4's short name), arm or disarm, else the command's name."""
    if command == "MAV_CMD_DO_SET_MODE":
        main, sub = _number(params, 1), _number(params, 2)
        if main is not None:
            return f"set mode {short_name(custom_mode(int(main), int(sub or 0)))}"
    if command == "SET_MODE" and (custom := _number(params, 1)) is not None:
        return f"set mode {short_name(int(custom))}"
    if command == "MAV_CMD_COMPONENT_ARM_DISARM" and (arm := _number(params, 0)) is not None:
        return "arm" if arm == 1.0 else "disarm"
    return command


def audit_events(doc: Mapping[str, Any], ns0: int, ns1: int) -> list[Event]:
    """The commands of ``doc``'s ``audit`` (gcs.mission.audit) at their times, within the
    run's [``ns0``, ``ns1``] (ns): each MAVLink record as ``agent/<vehicle>`` (``MAVLink set
    mode OFFBOARD: MAV_RESULT_ACCEPTED``; a refused one WARNING, telemetry requests
    DEBUG), each Zenoh command as ``gcs``, and the records dropped past the caps."""
    audit = doc.get("audit")
    if not isinstance(audit, Mapping):
        return []
    out: list[Event] = []
    for r in audit.get("mavlink") or []:
        if not isinstance(r, Mapping):
            continue
        cmd, ok = str(r.get("command")), bool(r.get("accepted"))
        why = f" ({r['reason']})" if r.get("reason") else ""
        how = f"link {r.get('link')}" + ("" if r.get("signed") else ", unsigned")
        lvl = (DEBUG if cmd in _TELEMETRY_COMMANDS else INFO) if ok else WARNING
        out.append(Event(_at(r.get("t"), ns0, ns1), lvl, f"agent/{r.get('vehicle')}",
                         f"MAVLink {mavlink_text(cmd, r.get('params'))}: {r.get('result')}"
                         f"{why} [{how}]"))
    for r in audit.get("zenoh") or []:
        if isinstance(r, Mapping):
            out.append(Event(_at(r.get("t"), ns0, ns1), INFO, "gcs", zenoh_text(r)))
    lost = sum(x for x in (audit.get("mavlink_dropped"), audit.get("zenoh_dropped"))
               if isinstance(x, int))
    if lost:
        out.append(Event(ns0, WARNING, "run", f"audit: {lost} commands past the caps not "
                         "listed"))
    return out


def zenoh_text(r: Mapping[str, Any]) -> str:
    """A Zenoh audit record (gcs.mission.audit.zenoh_record) in words: ``command land to
    all agents at 12 s``."""
    f = r.get("fields")
    f = f if isinstance(f, Mapping) else {}
    kind, agent = str(r.get("kind")), r.get("agent")
    text = f"command {kind}"
    if kind == "method":
        text += f" {f.get('method')}"
    elif kind == "outage":
        text += f" {f.get('duration_s')} s"
    text += " to all agents" if agent in (0, None) else f" to agent {agent}"
    at = _number([f.get("at_s")], 0)
    return text + (f" at {at:g} s" if at is not None and at >= 0.0 else "")


def all_events(doc: Mapping[str, Any], ns: np.ndarray, ids: Sequence[int],
               fallback: np.ndarray, alarms: np.ndarray, clipped: np.ndarray) -> list[Event]:
    """Every event of the run sorted by time (stable), at most :data:`MAX_EVENTS`."""
    if len(ns) == 0:
        return []
    ev = document_events(doc, int(ns[0]), int(ns[-1]))
    ev += series_events(ns, ids, fallback, alarms, clipped)
    ev.sort(key=lambda e: e.ns)
    return ev[:MAX_EVENTS]
