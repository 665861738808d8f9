"""The simulator's MAVLink I/O, one mixin of :class:`vehicle_sim.server.SimServer`.

Outbound: every vehicle's outbox and telemetry streams, packed per link (each link has its
own sequence numbers and signing stream, as PX4's MAVLink instances do) and sent to the
link's live destinations (each link its own default stream set, docs/px4/streams.md);
streams to unauthenticated peers within their per-peer byte budget. Inbound: decoded
messages to the vehicles, a hostile one counted, never fatal; an onboard component's
HEARTBEAT on the API link forwarded to the GCS link's peers.
Rejected-frame reports (STATUSTEXT) and the vehicles' event lines go to the log.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from typing import Any

from pymavlink.dialects.v20 import common as M

from swarm_common import signing
from swarm_common.enums import DefaultStreams
from vehicle_sim.autopilot.state import STATUSTEXT_LEN
from vehicle_sim.link.endpoint import MavlinkLink
from vehicle_sim.vehicle import Vehicle

ERRORS_LOGGED = 10  # per-packet errors logged before only counting them
REJECT_REPORT_S = 5.0  # at most one "rejected frames" STATUSTEXT per vehicle this often
PACK_ERRORS = (struct.error, ValueError, TypeError, OverflowError)  # field out of wire range
FORWARD_MIN_S = 0.5  # s between two forwarded HEARTBEATs of one component
_LOG_LEVEL = {
    M.MAV_SEVERITY_EMERGENCY: logging.CRITICAL,
    M.MAV_SEVERITY_ALERT: logging.CRITICAL,
    M.MAV_SEVERITY_CRITICAL: logging.CRITICAL,
    M.MAV_SEVERITY_ERROR: logging.ERROR,
    M.MAV_SEVERITY_WARNING: logging.WARNING,
    M.MAV_SEVERITY_NOTICE: logging.INFO,
    M.MAV_SEVERITY_INFO: logging.INFO,
    M.MAV_SEVERITY_DEBUG: logging.DEBUG,
}


def _signing_time_now() -> int:
    """The MAVLink signing timestamp of now (10 µs units since 2015-01-01)."""
    unix = time.time() - signing.SIGNATURE_EPOCH_UNIX_S
    return int(max(0.0, unix) * signing.TIMESTAMP_UNITS_PER_S)


class ServerIO:
    """MAVLink I/O of the simulator (the attributes are :class:`SimServer`'s)."""

    vehicles: list[Vehicle]
    vlinks: dict[int, dict[str, MavlinkLink]]
    touched: set[int]  # ids of the vehicles that received a message since the last poll
    forwarded: dict[tuple[int, int], float]
    handler_errors: int
    _rejects_reported: dict[int, tuple[int, float]]
    opts: Any
    clock: Any
    sel: Any

    def log(self, text: str, level: int = logging.INFO) -> None:
        raise NotImplementedError

    def flush(self, now: float) -> None:
        for v in self.vehicles:
            if not v.outbox and not v.stream_out:
                continue
            if self.opts.signing_key is not None:  # signing time never lags the wall clock
                for enc in v.encs.values():
                    enc.signing.timestamp = max(enc.signing.timestamp, _signing_time_now())
            links = self.vlinks[v.id]
            dests = {name: ln.destinations(now) for name, ln in links.items()}
            out, v.outbox = v.outbox, []
            for msg, dest in out:
                names = list(links) if dest is None else [dest[0]]
                for name in names:
                    buf = self._pack(v, msg, name)
                    if buf is None:
                        break
                    if dest is None or dest[1] is None:  # every destination of the link
                        links[name].send_bytes(buf, dests[name])
                    else:
                        links[name].send_bytes(buf, [], dest[1])
            self._flush_streams(v, now, dests)
        self.log_events()

    def _flush_streams(self, v: Vehicle, now: float, dests: dict[str, list]) -> None:
        """Telemetry: each link's default schedule to every destination of that link
        without its own, each peer's own schedule to it; unauthenticated peers within
        their byte budget (:meth:`MavlinkLink.stream_allowed`)."""
        links = self.vlinks[v.id]
        out, v.stream_out = v.stream_out, []
        custom = {name: v.streams.custom(name) for name in links}
        # --default-streams on-contact: a default remote nobody there has spoken from gets
        # the HEARTBEAT (so a ground station can find the vehicle) and nothing else
        silent = (
            {n: ln.default_remote for n, ln in links.items() if ln.default_remote not in ln.peers}
            if self.opts.default_streams is DefaultStreams.ON_CONTACT
            else {}
        )
        for msg, (name, addr) in out:
            link = links.get(name)
            if link is None:
                continue
            hb = msg.get_msgId() == M.MAVLINK_MSG_ID_HEARTBEAT
            if addr is None:
                skip = silent.get(name) if not hb else None
                targets = [d for d in dests[name] if d not in custom[name] and d != skip]
            else:
                targets = [addr]
            if not targets:
                continue
            buf = self._pack(v, msg, name)  # one frame per link: its own sequence
            if buf is None:
                continue
            for d in targets:
                if link.stream_allowed(d, len(buf), now, hb):
                    link.send_bytes(buf, [], d)

    def _pack(self, v: Vehicle, msg: M.MAVLink_message, link: str) -> bytes | None:
        try:
            return v.pack(msg, link)
        except PACK_ERRORS as exc:  # a field out of its wire range: drop, count
            self.handler_errors += 1
            if self.handler_errors <= ERRORS_LOGGED:
                self.log(f"vehicle {v.id}: cannot pack {msg.get_type()}: {exc!r}", logging.ERROR)
            return None

    def heartbeat_only(self, v: Vehicle) -> bool:
        """``--default-streams on-contact`` and no client on any of ``v``'s links takes its
        default schedule: the default telemetry is not even built (HEARTBEAT still goes)."""
        if self.opts.default_streams is not DefaultStreams.ON_CONTACT:
            return False
        for name, ln in self.vlinks[v.id].items():
            custom = v.streams.custom(name)
            if any(p not in custom for p in ln.peers):
                return False
        return True

    def live_peers(self, v: Vehicle) -> list[tuple[str, tuple[str, int]]]:
        return [(name, a) for name, ln in self.vlinks[v.id].items() for a in ln.peers]

    def report_rejects(self, now: float) -> None:
        """A STATUSTEXT (and log line) when a vehicle's links rejected frames since the
        last report, at most every ``REJECT_REPORT_S``."""
        for v in self.vehicles:
            sts = [ln.stats for ln in self.vlinks[v.id].values()]
            total = sum(st.rejected for st in sts)
            last, at = self._rejects_reported.get(v.id, (0, -REJECT_REPORT_S))
            if total == last or now - at < REJECT_REPORT_S:
                continue
            self._rejects_reported[v.id] = (total, now)
            u = sum(st.rejected_unsigned for st in sts)
            b = sum(st.rejected_bad_signature for st in sts)
            r = sum(st.rejected_replay for st in sts)
            text = f"rejected {u} unsigned {b} badsig {r} replay"
            v.event(text[:STATUSTEXT_LEN], M.MAV_SEVERITY_WARNING)

    def log_events(self) -> None:
        for v in self.vehicles:
            for severity, line in v.events:
                self.log(line, _LOG_LEVEL.get(severity, logging.INFO))
            v.events.clear()

    def receive(self, timeout: float) -> None:
        now = time.monotonic()
        t = self.clock.t()
        for key, _ in self.sel.select(max(0.0, timeout)):
            v, link = key.data
            self.touched.add(v.id)
            for m in link.receive(now):
                if link.name == "api" and m.get_msgId() == M.MAVLINK_MSG_ID_HEARTBEAT:
                    self._forward_component_heartbeat(v, m, now)
                try:
                    v.handle(m, (link.name, m._peer), now, t)
                except Exception as exc:  # noqa: BLE001 - logged and counted: a hostile
                    # message must never take the simulator down (handler_errors=0 in tests)
                    self.handler_errors += 1
                    if self.handler_errors <= ERRORS_LOGGED:
                        self.log(f"vehicle {v.id}: error handling {m.get_type()}: {exc!r}",
                                 logging.ERROR)  # fmt: skip

    def _forward_component_heartbeat(self, v: Vehicle, m: Any, now: float) -> None:
        """A HEARTBEAT of another component of this vehicle's system (the offboard daemon,
        component 191) arriving on the API link is forwarded to the GCS link's peers, as
        PX4 forwards between its MAVLink instances, so a ground station sees every
        component. At most one per component per FORWARD_MIN_S (no amplification)."""
        comp = m.get_srcComponent()
        if m.get_srcSystem() != v.id or comp == M.MAV_COMP_ID_AUTOPILOT1:
            return
        last = self.forwarded.get((v.id, comp), -math.inf)
        if now - last < FORWARD_MIN_S:
            return
        self.forwarded[(v.id, comp)] = now
        gcs = self.vlinks[v.id]["gcs"]
        gcs.forward_bytes(bytes(m.get_msgbuf()), gcs.destinations(now))
