"""A mission is startable the moment its upload is acknowledged: MAVSDK ``upload_mission``
then ``start_mission`` at once, 20 times in a row, on a loaded machine (a CPU hog beside
the simulator). Before the fix the final MISSION_ACK went out before the next simulation
step applied the new store, and a start sent right after it was DENIED ("no mission")."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from conftest import wait_for
from mavsdk_client import mavsdk_autopilot, position_ready

pytestmark = pytest.mark.timeout(120)
ONE = ["--no-zenoh", "--vehicles", "1"]
M_PER_DEG = 111_320.0  # metres per degree of latitude (flat earth, for offsets only)
ROUNDS = 20


def _plan(here: tuple[float, float], k: int):
    """Two waypoints a few metres from ``here``, different in every round."""
    from mavsdk.plugins.mission import MissionItem, MissionPlan

    lat, lon = here
    items = []
    for north, east in ((2.0 + 0.1 * k, 0.0), (2.0 + 0.1 * k, 2.0)):
        items.append(
            MissionItem(
                latitude_deg=lat + north / M_PER_DEG,
                longitude_deg=lon + east / (M_PER_DEG * math.cos(math.radians(lat))),
                relative_altitude_m=4.0, speed_m_s=2.0, is_fly_through=False,
                acceptance_radius_m=1.0, vehicle_action=MissionItem.VehicleAction.NONE,
            )
        )  # fmt: skip
    return MissionPlan(items)


def test_start_right_after_upload_ack_succeeds_every_time_under_load(sim_factory) -> None:
    pytest.importorskip("mavsdk")
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.mission import Mission
    from mavsdk.plugins.telemetry import Telemetry

    sim = sim_factory(ONE)
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        with mavsdk_autopilot(sim) as system:
            mis, act, tel = Mission(system), Action(system), Telemetry(system)
            assert wait_for(lambda: position_ready(tel), 10.0), sim.text()
            pos = tel.position()
            here = (pos.latitude_deg, pos.longitude_deg)
            act.arm()
            assert wait_for(tel.armed, 5.0), sim.text()
            failures: list[str] = []
            for k in range(ROUNDS):
                # leave AUTO.MISSION and drop the stored mission, so that a start which
                # raced the upload would find nothing and be DENIED
                act.hold()
                mis.clear_mission()
                mis.upload_mission(_plan(here, k))
                try:
                    mis.start_mission()
                except Exception as exc:  # MissionError: DENIED when the race is lost
                    failures.append(f"round {k}: {exc}")
            assert failures == [], "\n".join(failures) + "\n" + sim.text()
            assert mis.mission_progress().total == 2
    finally:
        hog.kill()
        hog.wait(5.0)
