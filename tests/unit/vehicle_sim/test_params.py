"""vehicle_sim.autopilot.params (store, file) and vehicle_sim.services.param (the MAVLink
protocol)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.params import (
    FILE_FORMAT,
    INT32,
    REAL32,
    ParamError,
    ParamFile,
    ParamFileError,
    ParamSpec,
    ParamStore,
    parse_param_file,
    read_param_file,
)
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.param import (
    LIST_BURST_MAX,
    LIST_PER_STEP,
    int32_to_wire,
    wire_to_int32,
)
from vehicle_sim.vehicle import Vehicle

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
GCS = ("gcs", ("127.0.0.1", 14550))
OTHER = ("api", ("127.0.0.1", 14540))


def _vehicle(agent_id: int = 1, **kw) -> Vehicle:
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    return Vehicle(agent_id, agent_id - 1, dyn, AutopilotConfig(**kw))


def _out(v: Vehicle, mid: int) -> list[tuple[object, object]]:
    return [(m, d) for m, d in v.outbox if m.get_msgId() == mid]


def _send(v: Vehicle, msg, src=GCS, restricted: bool = False) -> None:
    v.outbox.clear()
    msg._restricted = restricted
    v.handle(msg, src, 0.0, 1.0)


def _set_msg(name: str, value: float, ptype: int = REAL32, target: int = 1):
    return M.MAVLink_param_set_message(target, 1, name.encode(), value, ptype)


def _read_msg(name: str = "", index: int = -1):
    return M.MAVLink_param_request_read_message(1, 1, name.encode(), index)


# -- the table and the store -----------------------------------------------------------
def test_defaults_follow_the_vehicle_and_fit_their_ranges() -> None:
    v = _vehicle(3, offboard_timeout=0.8)
    p = v.params
    assert p.get("MAV_SYS_ID") == 3
    assert p.get("COM_OF_LOSS_T") == pytest.approx(0.8)
    hover = v.dyn.hold_thrust() / v.dyn.f_max
    assert p.get("MPC_THR_HOVER") == pytest.approx(hover, abs=1e-4)
    for s in p.specs:
        assert len(s.name) <= 16 and s.ptype in (INT32, REAL32)
        assert s.lo <= p.get(s.name) <= s.hi, s.name
        assert s.doc.startswith(("behaviour:", "identity:")), s.name
        assert s.read_only == s.doc.startswith("identity:"), s.name


def test_store_refuses_unknown_read_only_out_of_range_and_fractional_ints() -> None:
    p = _vehicle().params
    cases = {
        ("NOPE", 1.0): M.MAV_PARAM_ERROR_DOES_NOT_EXIST,
        ("MAV_SYS_ID", 2.0): M.MAV_PARAM_ERROR_READ_ONLY,
        ("MPC_THR_HOVER", 0.95): M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
        ("MPC_THR_HOVER", float("nan")): M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
        ("COM_OBL_RC_ACT", 2.5): M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
    }
    for (name, value), code in cases.items():
        with pytest.raises(ParamError) as ei:
            p.set(name, value)
        assert ei.value.code == code, name
    assert p.overrides == {}


def test_alias_writes_both_and_listeners_hear_both() -> None:
    p = _vehicle().params
    heard: list[list[str]] = []
    p.listeners.append(lambda _s, names: heard.append(names))
    p.set("MPC_TKO_ALT", 6.0)
    assert p.get("MIS_TAKEOFF_ALT") == p.get("MPC_TKO_ALT") == 6.0
    assert heard == [["MIS_TAKEOFF_ALT", "MPC_TKO_ALT"]]
    assert p.overrides == {"MIS_TAKEOFF_ALT": 6.0}


def test_int32_bytewise_encoding_round_trips_every_int_range_end() -> None:
    p = _vehicle().params
    assert int32_to_wire(1) == pytest.approx(1.401298464324817e-45)  # the bytes, not 1.0
    for s in p.specs:
        if s.ptype == INT32:
            for x in (int(s.lo), int(s.hi), int(s.default)):
                assert wire_to_int32(int32_to_wire(x)) == x, s.name


# -- the protocol ----------------------------------------------------------------------
def _long_table(v: Vehicle, extra: int = 40) -> None:
    """Give ``v`` a table longer than LIST_BURST_MAX (the paced path)."""
    specs = v.params.specs + [
        ParamSpec(f"TEST_P{k}", REAL32, 0.0, 0.0, 1.0, "behaviour: test") for k in range(extra)
    ]
    v.params = ParamStore(specs)


def _list_reply(v: Vehicle) -> list[tuple[object, object]]:
    return _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)


def test_short_list_comes_at_once_with_every_index_and_the_count() -> None:
    v = _vehicle()
    n = len(v.params)
    assert n <= LIST_BURST_MAX
    _send(v, M.MAVLink_param_request_list_message(1, 1))
    got = _list_reply(v)
    assert [m.param_index for m, _ in got] == list(range(n))
    assert {m.param_count for m, _ in got} == {n}
    assert {d for _, d in got} == {GCS}  # to the requester only
    by_name = {m.param_id: m for m, _ in got}
    assert wire_to_int32(by_name["MAV_SYS_ID"].param_value) == 1
    assert by_name["MAV_SYS_ID"].param_type == INT32
    assert by_name["MPC_THR_HOVER"].param_value == pytest.approx(v.params.get("MPC_THR_HOVER"))


def test_long_list_is_paced_and_gives_every_index_once() -> None:
    v = _vehicle()
    _long_table(v)
    n = len(v.params)
    _send(v, M.MAVLink_param_request_list_message(1, 1))
    assert _list_reply(v) == []  # nothing in the handler itself
    got = []
    for k in range(n):  # more steps than needed
        v.outbox.clear()
        v.param_service.update(k * 0.02)
        step = _list_reply(v)
        assert len(step) <= LIST_PER_STEP
        got += step
    assert sorted(m.param_index for m, _ in got) == list(range(n))
    assert {m.param_count for m, _ in got} == {n}
    assert {d for _, d in got} == {GCS}


def test_a_second_list_request_restarts_that_peer_only() -> None:
    v = _vehicle()
    _long_table(v)
    n = len(v.params)
    _send(v, M.MAVLink_param_request_list_message(1, 1), GCS)
    _send(v, M.MAVLink_param_request_list_message(1, 1), OTHER)
    v.param_service.update(0.0)  # the first LIST_PER_STEP of GCS's list go out
    _send(v, M.MAVLink_param_request_list_message(1, 0), GCS)
    pending = list(v.param_service.pending)
    assert [i for i, d in pending if d == GCS] == list(range(n))  # from the start again
    assert [i for i, d in pending if d == OTHER] == list(range(n))  # untouched


def test_read_by_name_and_by_index_and_unknown_gets_param_error() -> None:
    v = _vehicle()
    i = v.params.index["COM_OF_LOSS_T"]
    _send(v, _read_msg("COM_OF_LOSS_T"))
    ((m, d),) = _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)
    assert (m.param_id, m.param_index, d) == ("COM_OF_LOSS_T", i, GCS)
    _send(v, _read_msg("", i))
    ((m, _),) = _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)
    assert m.param_id == "COM_OF_LOSS_T"
    for msg in (_read_msg("NOT_A_PARAM"), _read_msg("", len(v.params))):
        _send(v, msg)
        assert _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE) == []
        ((e, d),) = _out(v, M.MAVLINK_MSG_ID_PARAM_ERROR)
        assert e.error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST and d == GCS
        assert _out(v, M.MAVLINK_MSG_ID_STATUSTEXT)


def test_set_answers_the_new_value_to_everyone() -> None:
    v = _vehicle()
    _send(v, _set_msg("MPC_THR_HOVER", 0.5))
    assert v.params.get("MPC_THR_HOVER") == 0.5
    ((m, d),) = _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)
    assert (m.param_id, m.param_value, d) == ("MPC_THR_HOVER", 0.5, None)
    _send(v, _set_msg("COM_OBL_RC_ACT", int32_to_wire(4), INT32))
    assert v.params.get("COM_OBL_RC_ACT") == 4
    ((m, _),) = _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)
    assert wire_to_int32(m.param_value) == 4
    _send(v, _set_msg("MIS_TAKEOFF_ALT", 9.0))
    assert {m.param_id for m, _ in _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)} == {
        "MIS_TAKEOFF_ALT", "MPC_TKO_ALT"}  # fmt: skip


@pytest.mark.parametrize(
    ("msg", "restricted", "code"),
    [
        (_set_msg("MPC_THR_HOVER", 2.0), False, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE),
        (_set_msg("COM_OBL_RC_ACT", 4.0), False, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE),  # type
        (_set_msg("MPC_THR_HOVER", 0.5, INT32), False, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE),
        (_set_msg("MAV_SYS_ID", int32_to_wire(2), INT32), False, M.MAV_PARAM_ERROR_READ_ONLY),
        (_set_msg("MPC_THR_HOVER", 0.5), True, M.MAV_PARAM_ERROR_PERMISSION_DENIED),
    ],
)
def test_refused_set_gets_error_unchanged_value_and_statustext(msg, restricted, code) -> None:
    v = _vehicle()
    before = list(v.params.values)
    _send(v, msg, restricted=restricted)
    assert v.params.values == before
    ((e, d),) = _out(v, M.MAVLINK_MSG_ID_PARAM_ERROR)
    assert (e.error, e.param_id, d) == (code, msg.param_id, GCS)
    ((pv, _),) = _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE)
    assert pv.param_id == msg.param_id and pv.param_index == v.params.index[msg.param_id]
    ((st, _),) = _out(v, M.MAVLINK_MSG_ID_STATUSTEXT)
    assert st.severity == M.MAV_SEVERITY_WARNING and msg.param_id in st.text


def test_unknown_set_gets_does_not_exist_and_no_value() -> None:
    v = _vehicle()
    _send(v, _set_msg("NOPE", 1.0))
    ((e, _),) = _out(v, M.MAVLINK_MSG_ID_PARAM_ERROR)
    assert e.error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST
    assert _out(v, M.MAVLINK_MSG_ID_PARAM_VALUE) == []


def test_other_components_and_systems_are_not_answered() -> None:
    v = _vehicle()
    _send(v, M.MAVLink_param_request_read_message(1, 191, b"MPC_THR_HOVER", -1))
    _send(v, _set_msg("MPC_THR_HOVER", 0.5, target=2))
    assert v.outbox == [] and v.params.overrides == {}


def test_every_reply_packs() -> None:
    v = _vehicle()
    for msg in (_read_msg("MAV_SYS_ID"), _set_msg("NOPE", 1.0), _set_msg("MPC_THR_HOVER", 9.0)):
        _send(v, msg)
        for m, _ in v.outbox:
            v.pack(m)


# -- the file --------------------------------------------------------------------------
def test_file_round_trip_keeps_other_vehicles_and_saves_atomically(tmp_path: Path) -> None:
    path = tmp_path / "params.json"
    doc = {
        "format": FILE_FORMAT,
        "vehicles": {"1": {"MPC_THR_HOVER": 0.4}, "9": {"NAV_ACC_RAD": 1}},
    }
    path.write_text(json.dumps(doc))
    v = _vehicle()
    pf = ParamFile(path, read_param_file(path, v.params))
    pf.attach(1, v.params)
    assert v.params.get("MPC_THR_HOVER") == 0.4
    _send(v, _set_msg("COM_OF_LOSS_T", 2.0))
    saved = json.loads(path.read_text())
    assert saved["vehicles"] == {
        "1": {"MPC_THR_HOVER": 0.4, "COM_OF_LOSS_T": 2.0}, "9": {"NAV_ACC_RAD": 1.0}}  # fmt: skip
    assert pf.saves == 1 and [p.name for p in tmp_path.iterdir()] == ["params.json"]
    _send(v, _set_msg("COM_OF_LOSS_T", 99.0))  # refused: not saved
    assert pf.saves == 1


def test_missing_file_is_empty(tmp_path: Path) -> None:
    assert read_param_file(tmp_path / "none.json", _vehicle().params) == {}


@pytest.mark.parametrize(
    ("doc", "words"),
    [
        ([], "exactly"),
        ({"format": "x", "vehicles": {}}, "format"),
        ({"format": FILE_FORMAT, "vehicles": {"0": {}}}, "vehicle key"),
        ({"format": FILE_FORMAT, "vehicles": {"a": {}}}, "vehicle key"),
        ({"format": FILE_FORMAT, "vehicles": {"1": []}}, "object"),
        ({"format": FILE_FORMAT, "vehicles": {"1": {"NOPE": 1}}}, "unknown parameter"),
        ({"format": FILE_FORMAT, "vehicles": {"1": {"MPC_THR_HOVER": 3}}}, "outside"),
        ({"format": FILE_FORMAT, "vehicles": {"1": {"MPC_THR_HOVER": "0.5"}}}, "not a number"),
        ({"format": FILE_FORMAT, "vehicles": {"1": {"COM_OBL_RC_ACT": True}}}, "not a number"),
        ({"format": FILE_FORMAT, "vehicles": {"1": {"MAV_SYS_ID": 4}}}, "read-only"),
    ],
)
def test_bad_files_are_one_line_errors(doc, words: str) -> None:
    with pytest.raises(ParamFileError, match=words) as ei:
        parse_param_file(doc, _vehicle().params)
    assert "\n" not in str(ei.value)


def test_unreadable_json_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "p.json"
    path.write_text("{not json")
    with pytest.raises(ParamFileError, match="not JSON"):
        read_param_file(path, _vehicle().params)
