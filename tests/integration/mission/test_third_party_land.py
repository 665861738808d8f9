"""A third-party client sends one top-layer follower to AUTO.LAND mid-run
(docs/lifecycle.md, "Third-party AUTO.LAND").

A real distributed lockstep run (vehicle-sim, eight offboard daemons, Zenoh, method dcbf)
of cube8. Once the cube has formed, a plain pymavlink client on the ground-station port
(system id 250, its own MAVLink connection) sends DO_SET_MODE AUTO.LAND to follower 3,
the top-layer vertex (0, 0, 1) with follower 4 (vertex (0, 0, 0)) 4 m below it. The
vehicle's own land controller brings it straight down at 0.7 m/s; its daemon keeps
publishing its measured state marked non-cooperative, and follower 4's filter takes the
whole avoidance budget against it.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
from conftest import CUBE8, MavClient, free_port_offset

from gcs.mission.distributed import recorded_metrics, run_distributed
from gcs.mission.launch_spec import SigningChoice
from swarm_common import px4
from swarm_common.ports import GCS_PORT
from swarm_common.scenario.model import load_scenario
from swarm_common.signing import generate_key, load_key, setup_signing

LANDER = 3  # top layer, vertex (0, 0, 1); follower 4 is below it
CMD_AT_S = 9.0  # mission time of the third party's command (cube8 forms by ~7 s)
DURATION_S = 21.0  # 6 m at 0.7 m/s plus margins
THIRD_PARTY_SYSID = 250
MAV = px4.mavutil.mavlink


class ThirdParty(threading.Thread):
    """A ground-station-like client: listens on the GCS port, and once vehicle LANDER's
    telemetry says mission time >= CMD_AT_S, sends it DO_SET_MODE AUTO.LAND until acked."""

    def __init__(self, port: int, key: bytes) -> None:
        super().__init__(daemon=True)
        self.client = MavClient(port, sysid=THIRD_PARTY_SYSID)
        # the swarm is signed (the default): the third party is another ground station of
        # the same operator, holding the swarm key (link id 7: its own stream)
        setup_signing(self.client.mav, key, 7)
        self.stop = threading.Event()
        self.sent_at_ms: int | None = None
        self.result: int | None = None

    def run(self) -> None:
        conn = self.client.conn
        last_send = 0.0
        while not self.stop.is_set() and self.result is None:
            m = conn.recv_match(blocking=True, timeout=0.2)
            if m is None or m.get_srcSystem() != LANDER:
                continue
            if m.get_type() == "COMMAND_ACK" and m.command == MAV.MAV_CMD_DO_SET_MODE:
                self.result = int(m.result)
                break
            ms = getattr(m, "time_boot_ms", None)
            if self.sent_at_ms is None and (ms is None or ms < CMD_AT_S * 1000):
                continue
            if time.monotonic() - last_send < 0.5:
                continue
            # udpin answers the last sender: this message came from vehicle LANDER's link
            conn.mav.command_long_send(
                LANDER, MAV.MAV_COMP_ID_AUTOPILOT1,
                MAV.MAV_CMD_DO_SET_MODE, 0,
                MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                px4.MAIN_AUTO, px4.SUB_AUTO_LAND, 0, 0, 0, 0,
            )
            if self.sent_at_ms is None:
                self.sent_at_ms = int(ms) if ms is not None else -1
            last_send = time.monotonic()


def test_third_party_auto_land_of_a_top_follower(tmp_path: Path) -> None:
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    key_path = tmp_path / "keys" / "swarm.key"
    generate_key(key_path)
    third = ThirdParty(GCS_PORT + off, load_key(key_path))
    third.start()
    try:
        rec, facts = run_distributed(
            sc, tmp_path, "dcbf", None, DURATION_S, port_offset=off, show_progress=False,
            signing=SigningChoice(key=key_path), processes=2,  # packed: the same run, cheaper
        )
    finally:
        third.stop.set()
        third.join(5)
        third.client.close()
    assert third.result == MAV.MAV_RESULT_ACCEPTED, third.result
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], DURATION_S)
    ids = list(sc.ids)
    lander, below = ids.index(LANDER), ids.index(4)
    p_end = ser.p[-1]
    after = ser.t >= CMD_AT_S
    d_pair = np.linalg.norm(ser.p[after, lander] - ser.p[after, below], axis=1)
    print(f"command sent at t={third.sent_at_ms} ms; wall {facts['wall_s']:.1f} s; "
          f"min distance {m['min_distance_m']:.3f} m, lander-follower 4 after the command "
          f"{d_pair.min():.3f} m; end z {np.round(p_end[:, 2], 2)}")
    logs = "\n".join(p.read_text(errors="replace") for p in tmp_path.glob("offboard-*.log"))
    assert f"agent {LANDER}: vehicle left OFFBOARD (LAND)" in logs
    assert m["collisions"] == 0
    assert m["min_distance_m"] >= 0.5
    # follower 4 was 4 m straight below the lander when the command came (cube formed)
    assert np.linalg.norm(ser.p[after, lander, :2][0] - ser.p[after, below, :2][0]) < 0.3
    assert d_pair.min() >= 1.0  # ... and got out of its way (measured 2.6 m)
    assert p_end[lander, 2] <= 0.1  # landed
    others = [i for i, aid in enumerate(ids) if aid not in sc.leader_ids and aid != LANDER]
    assert np.all(p_end[others, 2] >= 1.0), p_end[others, 2]  # the other followers fly on
