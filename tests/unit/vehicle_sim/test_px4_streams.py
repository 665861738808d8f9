"""PX4 default streams, health bits, the battery, information requests (vehicle_sim
telemetry / streams / info_service / battery / mavlink_extra), without sockets."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot import mavlink_extra, telemetry
from vehicle_sim.autopilot.config import DEFAULT_RATES, AutopilotConfig
from vehicle_sim.autopilot.streams import PeerStreams
from vehicle_sim.physics.battery import BatteryModel
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.command import Command, execute
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
ATT, VFR, ALT, BAT = (
    M.MAVLINK_MSG_ID_ATTITUDE,
    M.MAVLINK_MSG_ID_VFR_HUD,
    M.MAVLINK_MSG_ID_ALTITUDE,
    M.MAVLINK_MSG_ID_BATTERY_STATUS,
)
# MAVLink ids that pymavlink 2.4's common dialect does not define (QGC asks for them)
MSG_ID_COMPONENT_INFORMATION, MSG_ID_COMPONENT_METADATA = 395, 397
GCS_PEER = ("gcs", ("127.0.0.1", 40000))


def _vehicle() -> Vehicle:
    return Vehicle(1, 0, SwarmDynamics(load_scenario(CUBE8), held=True), AutopilotConfig())


def _wire(msg, sysid: int = 255, compid: int = 190):
    """``msg`` as a receiver sees it (header with the sender's ids)."""
    buf = msg.pack(M.MAVLink(None, srcSystem=sysid, srcComponent=compid))
    return M.MAVLink(None).parse_buffer(buf)[0]


def test_new_streams_are_on_by_default_and_build() -> None:
    v = _vehicle()
    for mid in (ATT, VFR, ALT, BAT, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE):
        assert DEFAULT_RATES[mid] > 0
        msg = telemetry.build(v, mid, 3.0)
        assert msg is not None and msg.get_msgId() == mid
        v.pack(msg)
    att = telemetry.build(v, ATT, 0.0)
    assert all(math.isfinite(x) for x in (att.roll, att.pitch, att.yaw))


def test_vfr_hud_and_altitude_follow_the_state() -> None:
    v = _vehicle()
    v.dyn.p[0] = [3.0, 4.0, 10.0]  # ENU, 10 m up
    v.dyn.v[0] = [3.0, 4.0, 1.5]
    hud = telemetry.vfr_hud(v, 0.0)
    assert hud.groundspeed == pytest.approx(5.0) and hud.airspeed == pytest.approx(5.0)
    assert hud.climb == pytest.approx(1.5) and hud.alt == pytest.approx(v.cfg.home_alt + 10.0)
    assert 0 <= hud.throttle <= 100 and 0 <= hud.heading < 360
    alt = telemetry.altitude(v, 2.0)
    assert alt.altitude_local == pytest.approx(10.0)
    assert alt.altitude_amsl == pytest.approx(v.cfg.home_alt + 10.0)
    assert alt.altitude_relative == pytest.approx(10.0) and alt.time_usec == 2_000_000


def test_sys_status_health_bits_geofence_battery_prearm() -> None:
    v = _vehicle()
    geo = M.MAV_SYS_STATUS_GEOFENCE
    st = telemetry.sys_status(v, 0.0)
    for field in ("present", "enabled", "health"):
        assert getattr(st, f"onboard_control_sensors_{field}") & geo
    assert st.onboard_control_sensors_health == st.onboard_control_sensors_present
    v.mission = SimpleNamespace(fence_breached=True)
    st = telemetry.sys_status(v, 0.0)
    assert st.onboard_control_sensors_present & geo and not st.onboard_control_sensors_health & geo
    v.info.battery.consumed_mah = v.info.battery.capacity_mah  # empty
    assert not telemetry.health(v) & M.MAV_SYS_STATUS_SENSOR_BATTERY
    v.terminate()
    assert not telemetry.health(v) & M.MAV_SYS_STATUS_PREARM_CHECK


def test_battery_drains_with_thrust_only_when_armed() -> None:
    def run(bm: BatteryModel, thrust: float, armed: bool) -> BatteryModel:
        for k in range(101):  # 10 s in 0.1 s steps
            bm.update(0.1 * k, thrust, 10.0, armed)
        return bm

    b = run(BatteryModel(), 20.0, armed=False)
    idle = b.consumed_mah
    assert idle == pytest.approx(b.idle_current_a * 10.0 / 3.6)
    hover, full = run(BatteryModel(), 10.0, True), run(BatteryModel(), 20.0, True)
    assert idle < hover.consumed_mah < full.consumed_mah  # T^1.5: twice the thrust, 2.8x
    assert full.current_a == pytest.approx(b.idle_current_a + b.hover_current_a * 2**1.5)
    assert 1.0 > hover.remaining > 0.99 and hover.voltage < BatteryModel().voltage
    hover.consumed_mah = 10 * hover.capacity_mah
    assert hover.remaining == 0.0 and hover.time_remaining_s() == 0 and hover.voltage > 0


def test_battery_status_reports_the_model() -> None:
    v = _vehicle()
    v.arm(0.0)
    for k in range(3001):  # a minute at (fixture) hover thrust, 50 Hz steps
        v.info.update(0.02 * k)
    bs = telemetry.battery_status(v, 60.0)
    b = v.info.battery
    assert bs.current_consumed == round(b.consumed_mah) > 0
    assert bs.battery_remaining == round(100 * b.remaining) < 100
    assert bs.voltages[: b.cells] == [round(1000 * b.cell_voltage)] * b.cells
    assert bs.voltages[b.cells] == 65535
    assert telemetry.sys_status(v, 60.0).voltage_battery == round(1000 * b.voltage)


def test_landed_state_takeoff_landing() -> None:
    v = _vehicle()
    v.dyn.p[0, 2] = 0.0
    assert telemetry.landed_state(v) == M.MAV_LANDED_STATE_ON_GROUND
    v.arm(0.0)
    v.nav = SimpleNamespace(kind="takeoff")
    assert telemetry.landed_state(v) == M.MAV_LANDED_STATE_TAKEOFF
    v.dyn.p[0, 2] = 5.0
    v.nav = SimpleNamespace(kind="land")
    assert telemetry.landed_state(v) == M.MAV_LANDED_STATE_LANDING
    v.nav = None
    assert telemetry.landed_state(v) == M.MAV_LANDED_STATE_IN_AIR


def test_autopilot_version_capabilities() -> None:
    caps = telemetry.autopilot_version(_vehicle(), 0.0).capabilities
    for bit in (
        M.MAV_PROTOCOL_CAPABILITY_MAVLINK2,
        M.MAV_PROTOCOL_CAPABILITY_MISSION_INT,
        M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
        M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT,
        M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
        M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
        M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET,
        M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
        M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY,
    ):
        assert caps & bit, bit


def test_protocol_version_message_round_trips() -> None:
    mavlink_extra.register()
    msg = _wire(telemetry.protocol_version(_vehicle(), 0.0))
    assert msg.get_type() == "PROTOCOL_VERSION"
    assert (msg.version, msg.min_version, msg.max_version) == (200, 100, 200)
    # the CRC seed formula reproduces a generated message's
    fields = (
        ("uint16_t", "message_rate", 0),
        ("uint8_t", "stream_id", 0),
        ("uint8_t", "on_off", 0),
    )
    assert mavlink_extra.crc_extra("DATA_STREAM", fields) == M.MAVLink_data_stream_message.crc_extra


def test_rate_set_by_a_peer_ends_when_it_goes_silent() -> None:
    s = PeerStreams(DEFAULT_RATES, 50.0)
    tgt = M.MAVLINK_MSG_ID_ATTITUDE_TARGET
    s.for_peer(GCS_PEER, create=True).set_interval(tgt, 100_000, 0.0)
    s.forget([GCS_PEER])
    assert s.for_peer(GCS_PEER).interval_us(tgt) == 100_000
    s.forget([])  # the link no longer counts it as present
    # the same address starts afresh, from its link's set (PX4 normal: 2 Hz)
    assert s.for_peer(GCS_PEER).interval_us(tgt) == 500_000
    assert GCS_PEER[1] not in s.custom("gcs")


def test_ping_request_is_answered_to_its_sender() -> None:
    v = _vehicle()
    req = _wire(M.MAVLink_ping_message(123456, 7, 0, 0), sysid=42, compid=190)
    v.handle(req, GCS_PEER, 1.0, 0.5)
    (msg, dest), *_ = v.outbox
    assert dest == GCS_PEER and msg.get_type() == "PING"
    assert (msg.time_usec, msg.seq, msg.target_system, msg.target_component) == (
        123456, 7, 42, 190,
    )  # fmt: skip
    v.outbox.clear()
    v.handle(_wire(M.MAVLink_ping_message(1, 8, 1, 1)), GCS_PEER, 1.0, 0.5)  # an answer
    assert v.outbox == []


def test_request_data_stream_sets_this_peers_group_rates() -> None:
    v = _vehicle()
    req = M.MAVLink_request_data_stream_message(1, 1, M.MAV_DATA_STREAM_EXTRA2, 10, 1)
    v.handle(_wire(req), GCS_PEER, 5.0, 0.0)
    msg, dest = v.outbox[-1]
    assert dest == GCS_PEER and msg.get_type() == "DATA_STREAM"
    assert (msg.stream_id, msg.message_rate, msg.on_off) == (M.MAV_DATA_STREAM_EXTRA2, 10, 1)
    assert v.streams.for_peer(GCS_PEER).interval_us(VFR) == 100_000
    assert v.streams.default.interval_us(VFR) == 250_000  # everyone else: 4 Hz
    stop = M.MAVLink_request_data_stream_message(1, 1, M.MAV_DATA_STREAM_ALL, 0, 0)
    v.handle(_wire(stop), GCS_PEER, 6.0, 0.0)
    assert v.outbox[-1][0].on_off == 0
    assert v.streams.for_peer(GCS_PEER).interval_us(ATT) == -1
    assert v.streams.for_peer(GCS_PEER).interval_us(M.MAVLINK_MSG_ID_HEARTBEAT) > 0
    unknown = M.MAVLink_request_data_stream_message(1, 1, 200, 5, 1)
    v.handle(_wire(unknown), GCS_PEER, 7.0, 0.0)
    assert v.outbox[-1][0].message_rate == 0  # answered, nothing changed


def test_protocol_version_and_home_position_commands() -> None:
    v = _vehicle()
    nan = math.nan
    res, reply = execute(v, Command(M.MAV_CMD_REQUEST_PROTOCOL_VERSION, (1, *[nan] * 6), 0, 0))
    assert res == M.MAV_RESULT_ACCEPTED and reply.get_type() == "PROTOCOL_VERSION"
    res, reply = execute(v, Command(M.MAV_CMD_GET_HOME_POSITION, (nan,) * 7, 0, 0))
    assert res == M.MAV_RESULT_ACCEPTED and reply.get_type() == "HOME_POSITION"
    for info in (MSG_ID_COMPONENT_INFORMATION, MSG_ID_COMPONENT_METADATA):
        res, _ = execute(v, Command(M.MAV_CMD_REQUEST_MESSAGE, (info, *[nan] * 6), 0, 0))
        assert res == M.MAV_RESULT_UNSUPPORTED
