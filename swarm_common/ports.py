"""UDP port scheme for N vehicles (docs/conventions.md §Ports).

PX4 SITL's convention for the first ten vehicles, extended so that 64+ vehicles
never collide (PX4's own scheme puts vehicle 11's API stream on 14550, the GCS port):

=====================  =============================  ============================
what                   vehicle i (1-based)             PX4 SITL (instance i-1)
=====================  =============================  ============================
API link, sim binds    14580 + (i-1)                   same
API link, sent to      14540 + (i-1) for i <= 10;      14540 + (i-1)
                       15000 + (i-11) for i >= 11
GCS link, sim binds    18570 + (i-1)                   same
GCS link, sent to      14550 (all vehicles)            same
=====================  =============================  ============================

A vehicle also answers every address that talks to it on either socket. Every port
is shifted by ``offset`` (``--port-offset``) so several swarms (or tests) can run side
by side. Valid for 1 <= i <= 255 (the MAVLink system id range): the highest port
used is 18570 + 254 + offset.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

GCS_PORT = 14550
API_LOCAL_BASE = 14580
API_REMOTE_BASE = 14540
API_REMOTE_HIGH_BASE = 15000
GCS_LOCAL_BASE = 18570
MAX_ID = 255


@dataclass(frozen=True)
class VehiclePorts:
    api_local: int
    api_remote: int
    gcs_local: int
    gcs_remote: int


def vehicle_ports(agent_id: int, offset: int = 0) -> VehiclePorts:
    """The four UDP ports of vehicle ``agent_id`` (1-based)."""
    if not 1 <= agent_id <= MAX_ID:
        raise ValueError(f"agent id {agent_id}: must be in [1, {MAX_ID}]")
    i = agent_id - 1
    api_remote = API_REMOTE_BASE + i if agent_id <= 10 else API_REMOTE_HIGH_BASE + (agent_id - 11)
    return VehiclePorts(
        api_local=API_LOCAL_BASE + i + offset,
        api_remote=api_remote + offset,
        gcs_local=GCS_LOCAL_BASE + i + offset,
        gcs_remote=GCS_PORT + offset,
    )


def port_free(
    port: int, kind: int = socket.SOCK_DGRAM, host: str = "127.0.0.1",
    allow_time_wait: bool = False,
) -> bool:
    """True if ``port`` can be bound on ``host`` right now (UDP by default).

    ``allow_time_wait``: for TCP, a port held only by a TIME_WAIT of a previous run counts
    as free (SO_REUSEADDR), as it will for a server that binds it the same way (Zenoh).
    """
    s = socket.socket(socket.AF_INET, kind)
    if allow_time_wait and kind == socket.SOCK_STREAM:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        s.bind((host, port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def swarm_udp_ports(ids: list[int], offset: int = 0) -> list[int]:
    """Every UDP port a swarm of these vehicle ids uses: the GCS port, then per vehicle
    its API link (both ends) and GCS link."""
    out = [GCS_PORT + offset]
    for i in ids:
        vp = vehicle_ports(i, offset)
        out += [vp.api_local, vp.api_remote, vp.gcs_local]
    return out
