"""Run statistics of ``vehicle-sim``: the ``stats:`` summary line and ``--stats-out`` JSON.

The summary is the last line the process writes to stderr (docs/conventions.md)::

    stats: steps=… collisions=… lockstep_timeouts=… handler_errors=… truth=… messages=…

The link counters include the signing rejects per reason (``rejected_unsigned``,
``rejected_bad_signature``, ``rejected_replay``), ``peers_refused`` and ``throttled``
(docs/security.md). ``audit``: every vehicle's audit trail of the commands it received
(:func:`vehicle_sim.autopilot.audit.stats_document`; docs/security.md, "Audit trail").
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Sequence
from typing import Any, Protocol

import numpy as np

from swarm_common.inputs import fallback_dir
from vehicle_sim.autopilot.audit import stats_document
from vehicle_sim.clock import LockstepClock, RealTimeClock
from vehicle_sim.link.endpoint import MavlinkLink
from vehicle_sim.link.truth import TruthPublisher
from vehicle_sim.options import SimOptions
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

log = logging.getLogger(__name__)

SUMMARY_KEYS = (
    "messages", "bad", "garbage", "truncated", "foreign", "setpoints", "setpoints_rejected",
    "setpoints_stale", "commands", "commands_unsupported", "commands_foreign", "failsafes",
    "rejected_unsigned", "rejected_bad_signature", "rejected_replay",
    "commands_unsigned_refused", "peers_refused", "throttled",
)  # fmt: skip
LATENCY_PERCENTILES = (50, 90, 99)


class RunState(Protocol):
    """What the statistics read of a running simulator (:class:`vehicle_sim.server.SimServer`)."""

    @property
    def opts(self) -> SimOptions: ...
    @property
    def clock(self) -> LockstepClock | RealTimeClock: ...
    @property
    def dyn(self) -> SwarmDynamics: ...
    @property
    def dt(self) -> float: ...
    @property
    def links(self) -> Sequence[MavlinkLink]: ...
    @property
    def vehicles(self) -> Sequence[Vehicle]: ...
    @property
    def truth_pub(self) -> TruthPublisher: ...
    @property
    def lockstep_timeouts(self) -> int: ...
    @property
    def handler_errors(self) -> int: ...


def latency_stats(vehicles: Iterable[Vehicle], dt: float) -> dict[str, Any]:
    """Setpoint-to-odometry latency over all vehicles (ms) and the fraction later than one
    control step ``dt`` (s)."""
    lat = np.array([x for v in vehicles for x in v.latency]) * 1000.0
    if lat.size == 0:
        return {"n": 0}
    q = np.percentile(lat, LATENCY_PERCENTILES)
    return {
        "n": int(lat.size),
        "p50_ms": float(q[0]),
        "p90_ms": float(q[1]),
        "p99_ms": float(q[2]),
        "max_ms": float(lat.max()),
        "late_fraction": float(np.mean(lat > dt * 1000.0)),
    }


def summary(sim: RunState) -> str:
    """The ``stats:`` line: server counters, then link and vehicle counters summed."""
    tot: dict[str, int] = {}
    for link in sim.links:
        for k, val in link.stats.as_dict().items():
            tot[k] = tot.get(k, 0) + val
    for v in sim.vehicles:
        for k, val in v.ctr.as_dict().items():
            tot[k] = tot.get(k, 0) + val
    body = " ".join(f"{k}={tot.get(k, 0)}" for k in SUMMARY_KEYS)
    return (
        f"stats: steps={sim.clock.k} collisions={sim.dyn.collisions} "
        f"lockstep_timeouts={sim.lockstep_timeouts} handler_errors={sim.handler_errors} "
        f"truth={sim.truth_pub.published} {body}"
    )


def _link_totals(sim: RunState) -> dict[str, int]:
    """Every link counter summed over the vehicles (signing rejects per reason, peers
    refused, streams throttled by the amplification bound, ...)."""
    tot: dict[str, int] = {}
    for link in sim.links:
        for k, val in link.stats.as_dict().items():
            tot[k] = tot.get(k, 0) + val
    return tot


def write_stats(sim: RunState, path: str) -> None:
    """``--stats-out``: mode, steps, timeouts, collisions, latency, the summary line and the
    audit trail."""
    doc = {
        "mode": "lockstep" if sim.opts.lockstep else "realtime",
        "steps": sim.clock.k,
        "lockstep_timeouts": sim.lockstep_timeouts,
        "collisions": sim.dyn.collisions,
        "latency": latency_stats(sim.vehicles, sim.dt),
        "relocks": getattr(sim.clock, "relocks", 0),
        "signing": sim.opts.signing_key is not None,
        "links": _link_totals(sim),
        "summary": summary(sim),
        "audit": stats_document([(v.id, v.audit) for v in sim.vehicles]),
    }
    write_json_or_fallback(doc, path)


def write_json_or_fallback(doc: dict[str, Any], path: str) -> str:
    """Write ``doc`` as JSON to ``path`` (checked writable at start, ``vehicle_sim.cli``);
    if that still fails, to ``stats.json`` in a fresh private temporary folder, logged
    with its path as an ERROR, so the statistics are never lost. Returns where it went."""
    text = json.dumps(doc, indent=2)
    try:
        with open(path, "w") as f:
            f.write(text)
        return path
    except OSError as exc:
        fallback = str(fallback_dir("vehicle-sim-stats-") / "stats.json")
        with open(fallback, "w") as f:
            f.write(text)
        log.error("cannot write stats to %s (%s): written to %s instead", path,
                  exc.strerror or exc, fallback)
        return fallback
