"""The formation vehicle served by the dashboard (gcs.dashboard.formation_link): an
unmodified pymavlink client on UDP talks to it while the dashboard's own steering keeps one
copy of the leaders' timeline. The Zenoh feed is a stand-in that records what is published
(the vehicle and its protocol are the ones of tests/integration/mission/test_formation_*)."""

from __future__ import annotations

import argparse
import time

import numpy as np
import pytest
from conftest import ROOT, free_port_offset
from pymavlink import mavutil

from gcs.dashboard.cli import configure_parser, run_dashboard
from gcs.dashboard.formation_link import FormationLink
from gcs.formation.steer import FormationSteer
from gcs.formation.vehicle import FORMATION_PORT, FORMATION_SYSID
from swarm_common import px4, wire
from swarm_common.scenario.model import load_scenario

MAV = mavutil.mavlink
COURSE8 = load_scenario(ROOT / "scenarios" / "course8.toml")


class Feed:
    """Truth and a mission time as the Zenoh feed would hold them; published commands kept."""

    def __init__(self, sc) -> None:
        self.truth = wire.Truth(step=0, t=0.0, ids=list(sc.ids), p=sc.initial_positions(),
                                v=np.zeros((sc.n, 3)), att=np.zeros((sc.n, 3)),
                                thrust=np.zeros(sc.n), lumped=np.zeros((sc.n, 3)))
        self.t: float | None = None
        self.published: list[wire.Command] = []

    def mission_time(self) -> float | None:
        return self.t

    def publish(self, cmd: wire.Command) -> str:
        self.published.append(cmd)
        return wire.key_cmd("course8", cmd.kind)


def test_a_client_holds_the_formation_through_the_dashboards_steering() -> None:
    port = FORMATION_PORT + free_port_offset()
    feed = Feed(COURSE8)
    steer = FormationSteer(COURSE8)
    link = FormationLink(COURSE8, feed, steer, port)
    client = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=245,
                                        source_component=190)
    try:
        quiet_until = time.monotonic() + 0.5  # silent before the swarm reports a time
        while time.monotonic() < quiet_until:
            client.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            link.tick()
            assert client.recv_match(type="HEARTBEAT", blocking=True, timeout=0.05) is None
        feed.t = 2.0  # course8 rests at its first waypoint until 10 s
        acked = None
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and acked is None:
            client.mav.command_long_send(FORMATION_SYSID, 1, MAV.MAV_CMD_DO_SET_MODE, 0,
                                         MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, px4.MAIN_AUTO,
                                         px4.SUB_AUTO_LOITER, 0, 0, 0, 0)
            for _ in range(10):
                link.tick()
                m = client.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.05)
                if m is not None and m.get_srcSystem() == FORMATION_SYSID:
                    acked = int(m.result)
                    break
    finally:
        client.close()
        link.close()
    assert acked == MAV.MAV_RESULT_ACCEPTED
    assert feed.published and feed.published[0].kind == "hold"
    assert steer.holding  # the dashboard's own steering saw it: one copy of the timeline


@pytest.mark.parametrize("extra", [["--scenario", str(ROOT / "scenarios" / "cube8.toml")],
                                   ["--scenario", str(ROOT / "scenarios" / "course8.toml"),
                                    "--no-zenoh"]])
def test_formation_vehicle_without_a_mission_or_zenoh_exits_2(extra, capsys) -> None:
    args = configure_parser(argparse.ArgumentParser()).parse_args(
        ["--formation-vehicle", "--port-offset", str(free_port_offset()), *extra])
    assert run_dashboard(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--formation-vehicle needs" in err[0]
