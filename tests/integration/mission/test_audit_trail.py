"""A run attacked with its own ground-station credentials lists every command in its
metrics (issue 42; docs/security.md, "Audit trail").

A real distributed lockstep run of cube8 (vehicle-sim, packed daemons, Zenoh), signed with
a key the test holds. While it runs, a pymavlink client on the ground-station port, signed
with that key (link id 200, as the dashboard), sends a handful of commands to several
vehicles: harmless ones (PARAM_SET of a default value, REQUEST_MESSAGE,
SET_MESSAGE_INTERVAL) and, late in the run, two mode changes to HOLD (DO_SET_MODE and a
SET_MODE message). ``metrics.json``'s ``audit.mavlink`` must list each of them (sender
system id, link, signed, result), the daemons' own arming and mode commands on the API
link, and ``audit.zenoh`` the runner's land-all command.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

from conftest import CUBE8, MavClient, free_port_offset

from gcs.mission.distributed import run_and_score
from gcs.mission.inproc import run_inproc
from gcs.mission.launch_spec import SigningChoice
from swarm_common import px4
from swarm_common.ports import GCS_PORT
from swarm_common.scenario.model import load_scenario
from swarm_common.signing import generate_key, load_key, setup_signing

ATTACKER_SYSID = 250
ATTACKER_COMPID = 190
GCS_SIGNING_LINK_ID = 200  # gcs.dashboard.link_tracker.GCS_SIGNING_LINK_ID
DURATION_S = 6.0
LAND_AT_S = 5.5
MAV = px4.mavutil.mavlink
HOLD = px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER)
# (vehicle, mission time s, what): sent once each, in this order
PLAN = (
    (2, 1.0, "param"),
    (5, 1.0, "request"),
    (6, 1.5, "interval"),
    (7, 2.0, "param"),
    (3, 4.0, "hold_cmd"),
    (8, 4.5, "hold_msg"),
)
AUDIT_NAME = {"param": "PARAM_SET", "request": "MAV_CMD_REQUEST_MESSAGE",
              "interval": "MAV_CMD_SET_MESSAGE_INTERVAL", "hold_cmd": "MAV_CMD_DO_SET_MODE",
              "hold_msg": "SET_MODE"}
ACCEPTED = {"param": "ACCEPTED", "request": "MAV_RESULT_ACCEPTED",
            "interval": "MAV_RESULT_ACCEPTED", "hold_cmd": "MAV_RESULT_ACCEPTED",
            "hold_msg": "MAV_RESULT_ACCEPTED"}


class Attacker(threading.Thread):
    """Listens on the GCS port; when vehicle ``v``'s telemetry says mission time >= the
    plan's, sends it the next command (udpin answers the last sender: that vehicle)."""

    def __init__(self, port: int, key: bytes) -> None:
        super().__init__(daemon=True)
        self.client = MavClient(port, sysid=ATTACKER_SYSID, compid=ATTACKER_COMPID)
        setup_signing(self.client.mav, key, GCS_SIGNING_LINK_ID)
        self.stop = threading.Event()
        self.sent: list[tuple[int, str, float]] = []  # (vehicle, what, mission time s)

    def _send(self, vid: int, what: str) -> None:
        mav = self.client.mav
        comp = MAV.MAV_COMP_ID_AUTOPILOT1
        if what == "param":
            mav.param_set_send(vid, comp, b"MPC_XY_VEL_MAX", 12.0, MAV.MAV_PARAM_TYPE_REAL32)
        elif what == "request":
            mav.command_long_send(vid, comp, MAV.MAV_CMD_REQUEST_MESSAGE, 0,
                                  MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        elif what == "interval":
            mav.command_long_send(vid, comp, MAV.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                  MAV.MAVLINK_MSG_ID_ATTITUDE, 200_000, 0, 0, 0, 0, 0)
        elif what == "hold_cmd":
            mav.command_long_send(vid, comp, MAV.MAV_CMD_DO_SET_MODE, 0,
                                  MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, px4.MAIN_AUTO,
                                  px4.SUB_AUTO_LOITER, 0, 0, 0, 0)
        else:
            mav.set_mode_send(vid, MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, HOLD)

    def run(self) -> None:
        todo = list(PLAN)
        conn = self.client.conn
        while todo and not self.stop.is_set():
            m = conn.recv_match(blocking=True, timeout=0.2)
            ms = getattr(m, "time_boot_ms", None) if m is not None else None
            vid, at_s, what = todo[0]
            if ms is None or m.get_srcSystem() != vid or ms < at_s * 1000:
                continue
            self._send(vid, what)
            self.sent.append((vid, what, ms / 1000.0))
            todo.pop(0)


def _from_attacker(audit: dict[str, Any]) -> list[dict[str, Any]]:
    return [r for r in audit["mavlink"] if r["sysid"] == ATTACKER_SYSID]


def test_every_command_of_an_attacker_with_the_runs_key_is_in_metrics(tmp_path: Path) -> None:
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    key_path = tmp_path / "keys" / "swarm.key"
    generate_key(key_path)
    attacker = Attacker(GCS_PORT + off, load_key(key_path))
    attacker.start()
    out = tmp_path / "run"
    try:
        run_and_score(sc, out, "dcbf", None, DURATION_S, port_offset=off, show_progress=False,
                      land_at=LAND_AT_S, signing=SigningChoice(key=key_path), processes=2)
    finally:
        attacker.stop.set()
        attacker.join(5)
        attacker.client.close()
    assert [(v, w) for v, w, _ in attacker.sent] == [(v, w) for v, _, w in PLAN]
    doc = json.loads((out / "metrics.json").read_text())
    audit = doc["audit"]
    assert "audit" not in doc["run"] and "audit" not in doc["run"]["simulator"]
    mine = _from_attacker(audit)
    print(json.dumps(mine, indent=1))
    # every command sent, once, in order, to the vehicle it was sent to
    assert [(r["vehicle"], r["command"]) for r in mine] == [
        (v, AUDIT_NAME[w]) for v, w, _ in attacker.sent]
    for r, (_vid, what, t_sent) in zip(mine, attacker.sent, strict=True):
        assert r["link"] == "gcs" and r["compid"] == ATTACKER_COMPID
        assert r["signed"] and not r["restricted"]
        assert r["result"] == ACCEPTED[what] and r["accepted"], r
        # stamped with the simulation time it was handled: after the telemetry it answered
        assert t_sent - 1e-6 <= r["t"] <= t_sent + 1.0, (r["t"], t_sent)
        assert r["peer"].startswith("127.0.0.1:")
    assert mine[0]["params"] == ["MPC_XY_VEL_MAX", 12.0, MAV.MAV_PARAM_TYPE_REAL32]
    assert mine[-1]["params"] == [MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, HOLD]
    # the daemons' own commands: every vehicle armed and switched to OFFBOARD on its API link
    api = [r for r in audit["mavlink"] if r["link"] == "api"]
    for vid in sc.ids:
        cmds = {r["command"] for r in api if r["vehicle"] == vid and r["accepted"]}
        assert {"MAV_CMD_COMPONENT_ARM_DISARM", "MAV_CMD_DO_SET_MODE"} <= cmds, (vid, cmds)
    assert all(r["signed"] for r in api)
    # the counts add up to the list
    n = sum(sum(per.values()) for name, per in audit["counts"].items()
            if not name.startswith("zenoh:"))
    assert n == len(audit["mavlink"]) and audit["mavlink_dropped"] == 0
    assert audit["counts"]["SET_MODE"]["MAV_RESULT_ACCEPTED"] >= 1
    # the runner's land-all on the swarm's Zenoh command key
    lands = [z for z in audit["zenoh"] if z["kind"] == "land"]
    assert lands and all(z["fields"]["at_s"] == LAND_AT_S and z["agent"] == 0 for z in lands)
    assert all(z["key"].endswith("/cmd/land") for z in lands)
    assert audit["counts"]["zenoh:land"]["seen"] == len(lands)
    t_first = lands[0]["t"]
    assert 0.0 <= t_first <= LAND_AT_S + 1.0


def test_inproc_run_records_its_scripted_land_like_the_distributed_one(tmp_path: Path) -> None:
    sc = load_scenario(CUBE8)
    res = run_inproc(sc, duration=0.2, land_at=0.1)
    res.save(tmp_path)
    audit = json.loads((tmp_path / "metrics.json").read_text())["audit"]
    assert audit["mavlink"] == []  # no simulator, no MAVLink
    [land] = audit["zenoh"]  # the scripted land-all, once, at the step it took effect
    assert (land["kind"], land["agent"], land["fields"]["at_s"]) == ("land", 0, 0.1)
    assert abs(land["t"] - 0.1) <= sc.control_dt + 1e-9
    assert land["key"].endswith(f"/{sc.name}/cmd/land")
    assert audit["counts"] == {"zenoh:land": {"seen": 1}}
