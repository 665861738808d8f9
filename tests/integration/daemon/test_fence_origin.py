"""The fence is read about the vehicle's own origin (docs/world.md, "A fence uploaded over
MAVLink"): ``vehicle-sim --home`` moves the vehicles' local frame 1.2 km from the default
origin; the simulator says so in GPS_GLOBAL_ORIGIN (streamed on the API link, and to an
unmodified pymavlink client that asks with MAV_CMD_REQUEST_MESSAGE), and the daemon's own
link and fence reader, on real UDP, find the scenario's box in what the vehicle stores,
where reading it about the default origin would find a box 1.2 km away."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from conftest import CUBE8, wait_for
from fence_client import BOX, request_message

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.fence_sync import FenceSync  # noqa: E402
from offboard.daemon.mavlink.link import VehicleLink  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.scenario.model import load_scenario  # noqa: E402
from swarm_common.world.geodesy import DEFAULT_ORIGIN, origin_offset_m  # noqa: E402
from swarm_common.world.mavlink_fence import read_fence, same_outline  # noqa: E402

pytestmark = pytest.mark.timeout(120)
M = mavutil.mavlink
HOME = (47.405742, 8.556594, 500.0)


def test_the_fence_is_read_about_the_vehicles_origin(sim_factory, tmp_path: Path) -> None:
    scenario = tmp_path / "cube8_fence.toml"
    scenario.write_text(Path(CUBE8).read_text() + BOX)
    box = load_scenario(scenario).world.geofence
    sim = sim_factory(["--no-zenoh", "--vehicles", "1", "--home", ",".join(map(str, HOME))],
                      scenario=str(scenario))
    ports = vehicle_ports(1, sim.offset)
    got = request_message(ports.gcs_local, 1, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
                          "GPS_GLOBAL_ORIGIN")
    assert (got.latitude, got.longitude) == (round(HOME[0] * 1e7), round(HOME[1] * 1e7))
    link = VehicleLink(f"udpin:127.0.0.1:{ports.api_remote}", 1, 50.0, lockstep=False)
    taken: list[object] = []
    sync = FenceSync(1, box, 0.5, lambda f: taken.append(f) is None)
    downloads = []

    def step() -> bool:  # the daemon's loop between two steps (OffboardDaemon.follow_fence)
        link.poll(0.05)
        now = time.monotonic()
        link.fence.tick(now)
        got = link.fence.take()
        if got is not None:
            downloads.append(got)
            sync.on_download(got, now)
        sync.on_origin(link.origin, now)
        return sync.read_about is not None

    try:
        assert wait_for(step, 30.0), sim.text()
    finally:
        link.close()
    assert link.origin is not None and origin_offset_m(link.origin, HOME[:2]) < 0.01
    assert sync.read_about == link.origin
    # the vehicle stores the scenario's box about its origin: nothing to take, no mismatch
    assert not taken and sync.fence is box and not sync.disagree and sync.alarm_bits() == 0
    _, items = downloads[-1]
    about_default = read_fence(items, DEFAULT_ORIGIN)
    assert about_default.kind == "polygon" and not same_outline(about_default.xy, box)
