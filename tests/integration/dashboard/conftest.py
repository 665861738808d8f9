"""Shared helpers for the dashboard tests."""

from __future__ import annotations

import random

import pytest

from swarm_common.ports import port_free, swarm_udp_ports


def free_port_offset(n_vehicles: int = 8) -> int:
    """A random port offset whose every port (GCS, API, vehicle links) is free now."""
    rng = random.Random()
    for _ in range(200):
        off = rng.randrange(1000, 30000)
        ports = swarm_udp_ports(list(range(1, n_vehicles + 1)), off)
        if all(port_free(p) for p in ports):
            return off
    raise RuntimeError("no free port offset found")


@pytest.fixture
def port_offset() -> int:
    return free_port_offset()
