"""Which ports a launched swarm binds, whether they are free, and a port offset whose
ports all are (``gcs mission run``/``compare`` without ``--port-offset``).

Every port is derived from the offset ``o`` (:mod:`swarm_common.ports`,
:mod:`gcs.mission.launch_spec`): per agent ``i`` the simulator binds UDP ``14580+i-1+o``
(API link) and ``18570+i-1+o`` (GCS link) and its daemon binds UDP ``14540+i-1+o`` (or
``15000+i-11+o`` above 10: the agent's API port); the ``gcs`` process hosts the Zenoh
router on TCP ``7447+o`` and the simulator listens on TCP ``7448+o``. The GCS port
(UDP ``14550+o``) is bound only by a ground station (the dashboard), and the formation
vehicle's (UDP ``14560+o``) only with ``--formation-vehicle``.

Probing is honest: each port is bound (as its owner will bind it), released, and only
then does the launch start. Another program may still take a port in between; the run then
fails on that port, and :func:`port_in_use_line` names it (exit 2).
"""

from __future__ import annotations

import logging
import re
import socket
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from swarm_common.ports import GCS_PORT, port_free, vehicle_ports
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT

log = logging.getLogger(__name__)

HOST = "127.0.0.1"
# offsets are tried in steps of this: every port of offset o + 1000 lies apart from every
# port of offset o whatever the number of agents (vehicle ports end in 540-835, 000-244,
# 570-824; Zenoh's in 447-448)
OFFSET_STEP = 1000


@dataclass(frozen=True)
class PortUse:
    """One port a swarm binds: ``proto`` "UDP" or "TCP", ``port`` on ``host``, and who
    binds it (``role``, e.g. "agent 1 API port")."""

    proto: str
    port: int
    role: str
    host: str = HOST

    def line(self) -> str:
        """``udp 14540 (127.0.0.1, agent 1 API port)``: protocol, port, address, role."""
        return f"{self.proto.lower()} {self.port} ({self.host}, {self.role})"

    def free(self) -> bool:
        """True if it can be bound right now (bound and released at once). TCP as Zenoh
        binds it: a TIME_WAIT left by an earlier run does not count as busy."""
        if self.proto == "UDP":
            return port_free(self.port, socket.SOCK_DGRAM, self.host)
        return port_free(self.port, socket.SOCK_STREAM, self.host, allow_time_wait=True)


def swarm_port_uses(
    agent_ids: Iterable[int], offset: int, zenoh: bool = True, gcs_port: bool = False,
    formation_port: int | None = None,
) -> list[PortUse]:
    """Every port a swarm of ``agent_ids`` binds at port offset ``offset``, in launch order
    (Zenoh router, simulator, daemons). ``gcs_port``: also the GCS port (a ground station's);
    ``formation_port``: the formation vehicle's UDP port (already offset)."""
    ids = list(agent_ids)
    out: list[PortUse] = []
    if zenoh:
        out += [PortUse("TCP", DEFAULT_ZENOH_PORT + offset, "Zenoh router"),
                PortUse("TCP", DEFAULT_ZENOH_PORT + offset + 1, "Zenoh simulator")]
    if gcs_port:
        out.append(PortUse("UDP", GCS_PORT + offset, "GCS port"))
    if formation_port is not None:
        out.append(PortUse("UDP", formation_port, "formation vehicle"))
    for i in ids:
        vp = vehicle_ports(i, offset)
        out += [PortUse("UDP", vp.api_local, f"vehicle {i} simulator API port"),
                PortUse("UDP", vp.gcs_local, f"vehicle {i} simulator GCS port")]
    for i in ids:
        out.append(PortUse("UDP", vehicle_ports(i, offset).api_remote, f"agent {i} API port"))
    return out


def busy_uses(uses: Iterable[PortUse]) -> list[PortUse]:
    """The ports of ``uses`` that cannot be bound now (each bound and released)."""
    return [u for u in uses if not u.free()]


def port_in_use_line(busy: list[PortUse], can_choose: bool = False) -> str:
    """One line naming the first busy port (and how many others are):
    ``udp 14540 (127.0.0.1, agent 1 API port) is in use; pick another --port-offset``;
    ``can_choose``: the command chooses free ports without ``--port-offset`` (says so)."""
    more = f" (and {len(busy) - 1} more)" if len(busy) > 1 else ""
    hint = ", or leave it out to choose free ports" if can_choose else ""
    return f"{busy[0].line()} is in use{more}; pick another --port-offset{hint}"


def choose_port_offset(
    agent_ids: Iterable[int], max_offset: int, zenoh: bool = True, gcs_port: bool = False,
    formation_base: int | None = None, step: int = OFFSET_STEP, start: int = 0,
) -> int | None:
    """The first offset ``start``, ``start + step``, ... (at most ``max_offset``) at which
    every port of :func:`swarm_port_uses` is free; None when there is none. Logged (INFO)
    when it is not ``start``, naming the port that was in use there.
    ``formation_base``: the formation vehicle's port at offset 0 (its port moves with the
    offset too)."""
    ids = list(agent_ids)
    first_busy: PortUse | None = None
    for off in range(start, max_offset + 1, step):
        fport = None if formation_base is None else formation_base + off
        busy = busy_uses(swarm_port_uses(ids, off, zenoh, gcs_port, fport))
        if not busy:
            if first_busy is None:  # the usual case: said only at debug level, so that a
                # refusal that follows (a bad key file) stays the only line on stderr
                log.debug("port offset %d chosen (every port free)", off)
            else:
                log.info("port offset %d chosen: at offset %d, %s was in use", off, start,
                         first_busy.line())
            return off
        first_busy = busy[0] if first_busy is None else first_busy
        log.debug("port offset %d: %d port(s) in use, first %s", off, len(busy),
                  busy[0].line())
    return None


def bind_failure_line(name: str, cause: str, log_path: Path, mine: list[PortUse]) -> str | None:
    """When ``cause`` (the last error line of child ``name``'s log) says an address was in
    use (another program took a port between the probe and the launch): one line naming
    the port, the one in ``cause``, else the one of ``mine`` (the child's ports) busy now,
    else all of ``mine``; None for any other cause."""
    if "in use" not in cause and "Errno 98" not in cause:
        return None
    named = [u for u in mine if re.search(rf"(?<!\d){u.port}(?!\d)", cause)]
    busy = named or busy_uses(mine)
    if busy:
        which = busy[0].line()
    else:
        which = "one of " + ", ".join(u.line() for u in mine) if mine else "a port"
    return (f"{which} is in use: {name} could not bind it ({cause}; log: {log_path}); "
            "another program took it after the check: run again, or pick another "
            "--port-offset")
