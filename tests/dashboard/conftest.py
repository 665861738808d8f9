"""Shared helpers for the dashboard tests."""

from __future__ import annotations

import random
import socket

import pytest

from swarm_common.ports import vehicle_ports


def _udp_free(port: int) -> bool:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def free_port_offset(n_vehicles: int = 8) -> int:
    """A random port offset whose every port (GCS, API, vehicle links) is free now."""
    rng = random.Random()
    for _ in range(200):
        off = rng.randrange(1000, 30000)
        ports = {14550 + off}
        for i in range(1, n_vehicles + 1):
            vp = vehicle_ports(i, off)
            ports |= {vp.api_local, vp.api_remote, vp.gcs_local}
        if all(_udp_free(p) for p in ports):
            return off
    raise RuntimeError("no free port offset found")


@pytest.fixture
def port_offset() -> int:
    return free_port_offset()
