"""The simulator reports a stored fence that a ground station changed in its Zenoh truth
(``wire.Truth.fences``; docs/world.md, "Scored from the truth"), so a run's verdict scores
the fence each vehicle enforces: ``vehicle-sim`` in real time, an unmodified pymavlink
client uploading a pentagon over the mission protocol on the GCS link, a real Zenoh
subscriber to the truth."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import CUBE8, free_port_offset, wait_for
from fence_client import BOX, PENTAGON, upload_fence

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from swarm_common import wire  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT, open_session  # noqa: E402

pytestmark = pytest.mark.timeout(120)
M = mavutil.mavlink


def test_an_uploaded_fence_reaches_the_truth_once(sim_factory, tmp_path: Path) -> None:
    scenario = tmp_path / "cube8_fence.toml"
    scenario.write_text(Path(CUBE8).read_text() + BOX)
    off = free_port_offset()
    sim = sim_factory(["--vehicles", "1", "--swarm", "ft"], offset=off, scenario=str(scenario))
    lock = threading.Lock()
    seen: list[wire.Truth] = []

    def got(sample) -> None:
        msg = wire.decode(sample.payload.to_bytes())
        with lock:
            seen.append(msg)

    sess = open_session(connect=[f"tcp/127.0.0.1:{DEFAULT_ZENOH_PORT + off}"])
    sub = sess.declare_subscriber(wire.key_truth("ft"), got)
    try:
        assert wait_for(lambda: len(seen) > 10, 30.0), sim.text()
        with lock:  # the scenario's own fence, stored from the start: never reported
            assert not any(isinstance(t, wire.Truth) and t.fences for t in seen)
        assert upload_fence(vehicle_ports(1, off).gcs_local, PENTAGON, 1) == M.MAV_MISSION_ACCEPTED
        n0 = len(seen)
        assert wait_for(lambda: len(seen) > n0 + 20, 30.0), sim.text()
    finally:
        sub.undeclare()
        sess.close()
    with lock:
        changed = [t for t in seen if isinstance(t, wire.Truth) and t.fences]
    assert len(changed) == 1, [t.step for t in changed]  # once, on the step after the upload
    xy = changed[0].fences[1].reshape(-1, 2)
    assert np.allclose(xy, PENTAGON, atol=0.02)  # the degE7 round trip: about 1 cm
