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
