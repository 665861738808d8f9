"""The simulator's lockstep wait (``SimServer.lockstep_poll``): between full scans only
the vehicles that received a datagram are re-checked, and a full scan still decides
every step. Driven on a real ``SimServer`` (its UDP links bound on 127.0.0.1, no Zenoh)
with explicit ``now`` values, so nothing depends on scheduling."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import free_port_offset  # noqa: E402

from swarm_common.enums import VehicleMode
from swarm_common.scenario.model import load_scenario
from vehicle_sim.clock import LockstepClock
from vehicle_sim.options import SimOptions
from vehicle_sim.server import LOCKSTEP_SCAN_S, SimServer

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"


@pytest.fixture
def server() -> Iterator[SimServer]:
    opts = SimOptions(lockstep=True, zenoh=False, port_offset=free_port_offset(),
                      step_timeout=30.0)
    srv = SimServer(load_scenario(CUBE8), opts)
    try:
        yield srv
    finally:
        srv.close()


def _flying(srv: SimServer) -> float:
    """Every vehicle armed in OFFBOARD and answering; the barrier passed, step begun now."""
    clk = srv.clock
    assert isinstance(clk, LockstepClock)
    for v in srv.vehicles:
        v.armed, v.mode, v.failsafe, v.ever_answered = True, VehicleMode.OFFBOARD, False, True
    clk.started = True
    now = clk.wall()
    clk.begin_step(now)
    return now


def _answer(srv: SimServer, ids: list[int]) -> None:
    """Vehicles ``ids`` answer the current step (as their setpoint handler records it)."""
    ms = srv.clock.t_ms()
    for vid in ids:
        srv.vehicle_by_id[vid].answered_ms = ms
    srv.touched |= set(ids)


def test_the_step_is_taken_when_the_last_answer_arrives(server: SimServer) -> None:
    now = _flying(server)
    k0 = server.clock.k
    ids = [v.id for v in server.vehicles]
    server.lockstep_poll(now)  # full scan: everyone still to answer
    assert server.clock.k == k0
    _answer(server, ids[:-1])
    server.lockstep_poll(now + 1e-4)  # within the scan window: one still missing
    assert server.clock.k == k0
    _answer(server, ids[-1:])
    server.lockstep_poll(now + 2e-4)  # the set ran empty: a full scan steps at once
    assert server.clock.k == k0 + 1


def test_an_answer_not_seen_by_the_incremental_check_is_found_by_the_full_scan(
    server: SimServer,
) -> None:
    """A vehicle that stops being waited for without sending anything (here: it left
    OFFBOARD) is not among the touched ones; the next full scan, at most LOCKSTEP_SCAN_S
    later, still takes the step."""
    now = _flying(server)
    k0 = server.clock.k
    ids = [v.id for v in server.vehicles]
    server.lockstep_poll(now)
    _answer(server, ids[1:])
    server.vehicle_by_id[ids[0]].mode = VehicleMode.HOLD  # silently no longer waited for
    server.lockstep_poll(now + 1e-4)
    assert server.clock.k == k0  # not yet looked at
    server.lockstep_poll(now + LOCKSTEP_SCAN_S + 1e-4)
    assert server.clock.k == k0 + 1


def test_a_touched_vehicle_that_did_not_answer_is_still_waited_for(server: SimServer) -> None:
    now = _flying(server)
    k0 = server.clock.k
    ids = [v.id for v in server.vehicles]
    server.lockstep_poll(now)
    _answer(server, ids[1:])
    server.touched.add(ids[0])  # a datagram that was not this step's setpoint
    server.lockstep_poll(now + 1e-4)
    server.lockstep_poll(now + LOCKSTEP_SCAN_S + 1e-4)  # a full scan agrees
    assert server.clock.k == k0
