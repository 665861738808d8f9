"""The ``/events`` of a record (foxglove.Log, docs/records.md): what a run's documents say
happened, on the sim clock. No I/O.

From ``metrics.json``: the start (scenario, method, seed), each ``safety_alarms`` entry,
the agents that failed (a distributed run's ``run.failed_agents``) and the end (verdict).
From the series: each agent's QP falling back and recovering (``fallback``), the onsets of
its :class:`~swarm_common.enums.AgentAlarm` bits and of input clipping.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm_common.enums import AgentAlarm

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
    run = doc.get("run")
    failed = run.get("failed_agents") if isinstance(run, Mapping) else None
    if failed:
        out.append(Event(ns1, ERROR, "run", f"failed agents: {failed}"))
    if doc.get("aborted"):
        out.append(Event(ns1, ERROR, "run", "aborted"))
    out.append(Event(ns1, INFO, "run", f"end: safety verdict {m.get('safety_verdict')}, "
                     f"min distance {m.get('min_distance_m')} m"))
    return out


def all_events(doc: Mapping[str, Any], ns: np.ndarray, ids: Sequence[int],
               fallback: np.ndarray, alarms: np.ndarray, clipped: np.ndarray) -> list[Event]:
    """Every event of the run sorted by time (stable), at most :data:`MAX_EVENTS`."""
    if len(ns) == 0:
        return []
    ev = document_events(doc, int(ns[0]), int(ns[-1]))
    ev += series_events(ns, ids, fallback, alarms, clipped)
    ev.sort(key=lambda e: e.ns)
    return ev[:MAX_EVENTS]
