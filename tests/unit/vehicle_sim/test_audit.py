"""The simulator's audit trail (vehicle_sim.autopilot.audit; docs/security.md, "Audit
trail"): one record per command-like message, bounded per vehicle, JSON-ready."""

from __future__ import annotations

import json
import math
from pathlib import Path

from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.audit import AUDIT_CAP, AuditLog, enum_name, record, stats_document
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
GCS = ("gcs", ("127.0.0.1", 14550))
API = ("api", ("127.0.0.1", 14580))
KEYS = {"t", "vehicle", "link", "peer", "sysid", "compid", "signed", "restricted", "command",
        "params", "result", "accepted", "reason"}


def _vehicle(agent_id: int = 2) -> Vehicle:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    return Vehicle(agent_id, agent_id - 1, dyn, AutopilotConfig())


def _wire(msg, sysid: int = 255, compid: int = 190, restricted: bool = False):
    """``msg`` as the receiver decodes it (header with the sender's ids)."""
    buf = msg.pack(M.MAVLink(None, srcSystem=sysid, srcComponent=compid))
    m = M.MAVLink(None).parse_buffer(buf)[0]
    m._restricted = restricted
    return m


def _long(target: int, cmd: int, *p: float):
    ps = [float(x) for x in p] + [math.nan] * (7 - len(p))
    return M.MAVLink_command_long_message(target, 1, cmd, 0, *ps)


def test_each_command_kind_is_recorded_with_sender_link_and_result() -> None:
    v = _vehicle(2)
    v.handle(_wire(_long(2, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)),
             GCS, 0.0, 1.5)
    # a flight command from an unsigned peer on a signed link: refused, with its reason
    v.handle(_wire(_long(2, M.MAV_CMD_COMPONENT_ARM_DISARM, 1), restricted=True), GCS, 0.0, 2.0)
    v.handle(_wire(_long(2, 31999)), GCS, 0.0, 2.5)  # a command nobody implements
    mode = M.MAVLink_set_mode_message(2, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                      px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER))
    v.handle(_wire(mode, sysid=1, compid=191), API, 0.0, 3.0)
    v.handle(_wire(M.MAVLink_param_set_message(2, 1, b"MPC_XY_VEL_MAX", 11.0,
                                                M.MAV_PARAM_TYPE_REAL32)), GCS, 0.0, 3.5)
    v.handle(_wire(M.MAVLink_param_set_message(2, 1, b"NO_SUCH_PARAM", 1.0,
                                                M.MAV_PARAM_TYPE_REAL32)), GCS, 0.0, 4.0)
    v.handle(_wire(M.MAVLink_param_set_message(2, 1, b"MPC_XY_VEL_MAX", 11.0,
                                                M.MAV_PARAM_TYPE_REAL32), restricted=True),
             GCS, 0.0, 4.5)
    v.handle(_wire(M.MAVLink_mission_clear_all_message(2, 1, M.MAV_MISSION_TYPE_MISSION)),
             GCS, 0.0, 5.0)
    v.handle(_wire(M.MAVLink_mission_set_current_message(2, 1, 7)), GCS, 0.0, 5.5)
    v.handle(_wire(M.MAVLink_mission_count_message(2, 1, 0, M.MAV_MISSION_TYPE_FENCE),
                   restricted=True), GCS, 0.0, 6.0)
    # telemetry, setpoints and messages for another vehicle leave no record
    v.handle(_wire(_long(5, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)), GCS, 0.0, 6.5)
    v.handle(_wire(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)), GCS, 0.0, 7.0)
    recs = v.audit.records
    got = [(r["t"], r["command"], r["result"], r["accepted"]) for r in recs]
    assert got == [
        (1.5, "MAV_CMD_REQUEST_MESSAGE", "MAV_RESULT_ACCEPTED", True),
        (2.0, "MAV_CMD_COMPONENT_ARM_DISARM", "MAV_RESULT_DENIED", False),
        (2.5, "MAV_CMD 31999", "MAV_RESULT_UNSUPPORTED", False),
        (3.0, "SET_MODE", "MAV_RESULT_ACCEPTED", True),
        (3.5, "PARAM_SET", "ACCEPTED", True),
        (4.0, "PARAM_SET", "MAV_PARAM_ERROR_DOES_NOT_EXIST", False),
        (4.5, "PARAM_SET", "MAV_PARAM_ERROR_PERMISSION_DENIED", False),
        (5.0, "MISSION_CLEAR_ALL", "MAV_MISSION_ACCEPTED", True),
        (5.5, "MISSION_SET_CURRENT", "MAV_MISSION_INVALID_SEQUENCE", False),
        (6.0, "MISSION_UPLOAD", "MAV_MISSION_DENIED", False),
    ], got
    assert all(set(r) == KEYS and r["vehicle"] == 2 for r in recs)
    assert recs[0]["link"] == "gcs" and recs[0]["peer"] == "127.0.0.1:14550"
    assert (recs[0]["sysid"], recs[0]["compid"]) == (255, 190)
    assert recs[0]["params"][0] == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
    assert recs[0]["params"][1:] == [None] * 6  # NaN (unused) as null
    assert recs[1]["restricted"] and not recs[0]["restricted"]
    assert "unsigned" in recs[1]["reason"]
    assert (recs[3]["link"], recs[3]["sysid"], recs[3]["compid"]) == ("api", 1, 191)
    assert recs[3]["params"] == [M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                 px4.custom_mode(px4.MAIN_AUTO, px4.SUB_AUTO_LOITER)]
    assert recs[4]["params"] == ["MPC_XY_VEL_MAX", 11.0, M.MAV_PARAM_TYPE_REAL32]
    assert "unknown parameter" in recs[5]["reason"]
    assert recs[9]["params"] == [M.MAV_MISSION_TYPE_FENCE]
    assert not any(r["signed"] for r in recs)  # none of these frames carried a signature
    json.dumps(recs, allow_nan=False)  # strict JSON: no NaN anywhere


def test_the_list_keeps_the_first_cap_records_and_counts_the_rest() -> None:
    assert AUDIT_CAP == 5000
    v = _vehicle(3)
    v.audit = AuditLog(cap=4)
    for k in range(11):
        v.handle(_wire(_long(3, M.MAV_CMD_GET_MESSAGE_INTERVAL, 30)), GCS, 0.0, float(k))
    assert [r["t"] for r in v.audit.records] == [0.0, 1.0, 2.0, 3.0]
    assert v.audit.dropped == 7
    assert v.audit.as_dict()["cap"] == 4 and len(v.audit.as_dict()["records"]) == 4


def test_stats_document_merges_vehicles_in_time_order() -> None:
    a, b = _vehicle(1), _vehicle(2)
    a.audit, b.audit = AuditLog(cap=2), AuditLog(cap=2)
    for v, t in ((a, 2.0), (b, 1.0), (a, 0.5), (b, 3.0), (b, 4.0), (b, 5.0)):
        record(v, _wire(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)), GCS, t, "X", [t],
               "ACCEPTED", True)
    doc = json.loads(json.dumps(stats_document([(1, a.audit), (2, b.audit)])))
    assert [(r["t"], r["vehicle"]) for r in doc["records"]] == [
        (0.5, 1), (1.0, 2), (2.0, 1), (3.0, 2)]
    assert doc["dropped"] == 2 and doc["dropped_per_vehicle"] == {"2": 2}
    assert doc["cap_per_vehicle"] == 2
    empty = stats_document([])
    assert empty["records"] == [] and empty["dropped"] == 0


def test_enum_names() -> None:
    assert enum_name("MAV_CMD", M.MAV_CMD_DO_SET_MODE) == "MAV_CMD_DO_SET_MODE"
    assert enum_name("MAV_RESULT", M.MAV_RESULT_DENIED) == "MAV_RESULT_DENIED"
    assert enum_name("MAV_RESULT", 250) == "MAV_RESULT 250"
