"""The record's ROS 2 message bodies and events (gcs.records.payloads, gcs.records.events):
CDR bytes decoded by an independent decoder (mcap-ros2-support's, from the schema text),
NaN and inf kept bit for bit, the padding rule enforced; events at the right steps."""

from __future__ import annotations

import numpy as np
import pytest
from foxglove.messages import SceneUpdate
from mcap.records import Schema as McapSchema
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoder
from mcap_ros2._dynamic import generate_dynamic

from gcs.records import topics as tp
from gcs.records.events import DEBUG, INFO, WARNING, all_events, document_events, series_events
from gcs.records.payloads import cdr_rows, layout
from swarm_common.enums import AgentAlarm

pytestmark = pytest.mark.unit


def _decoder(name: str, fields: tuple[tuple[str, str, str], ...]):
    return generate_dynamic(name, tp.ros2msg(fields))[name]


def test_qp_rows_decode_independently() -> None:
    rng = np.random.default_rng(3)
    k = 7
    vals = {"t_s": np.arange(k) * 0.02, "u_m_s2": rng.normal(size=(k, 3)),
            "h_min_m2": np.r_[np.inf, np.nan, rng.normal(size=k - 2)],
            "solve_us": rng.uniform(0, 100, k), "thrust_n": rng.uniform(0, 50, k),
            "tilt_deg": rng.uniform(0, 30, k), "degraded": np.arange(k) % 2 == 1,
            "input_clipped": np.arange(k) % 3 == 0, "alarms": np.arange(k) % 16,
            "u_nom_m_s2": rng.normal(size=(k, 3)), "correction_m_s2": rng.uniform(0, 5, k),
            "clf_slack_m_s2": np.r_[np.nan, rng.uniform(0, 1, k - 1)],
            "relax_m_s2": rng.uniform(0, 1e-3, k), "qp_status": np.r_[255, np.arange(k - 1) % 4],
            "active_rows": np.arange(k) * 40, "active_kinds": np.arange(k) * 9 % 64}
    rows = cdr_rows(tp.QP_FIELDS, vals, k)
    dec = _decoder(tp.QP_SCHEMA, tp.QP_FIELDS)
    for r, raw in enumerate(rows):
        m = dec(raw)
        assert m.t_s == vals["t_s"][r]
        assert list(m.u_m_s2) == vals["u_m_s2"][r].tolist()
        np.testing.assert_array_equal(m.h_min_m2, vals["h_min_m2"][r])  # inf, NaN kept
        assert bool(m.degraded) == bool(vals["degraded"][r])
        assert bool(m.input_clipped) == bool(vals["input_clipped"][r])
        assert m.alarms == vals["alarms"][r]
        assert list(m.u_nom_m_s2) == vals["u_nom_m_s2"][r].tolist()
        for f in ("correction_m_s2", "clf_slack_m_s2", "relax_m_s2"):
            np.testing.assert_array_equal(getattr(m, f), vals[f][r])
        for f in ("qp_status", "active_rows", "active_kinds"):
            assert getattr(m, f) == vals[f][r]


def test_pairs_rows_decode_independently() -> None:
    k, npair = 4, 3
    fields = tp.pairs_fields(npair)
    vals = {"t_s": np.arange(k, dtype=float), "min_distance_m": np.full(k, 1.5),
            "min_h_m2": np.full(k, -0.25), "distance_m": np.arange(k * npair).reshape(k, npair),
            "h_m2": -np.arange(k * npair).reshape(k, npair) / 7,
            "i": np.tile([1, 1, 2], (k, 1)), "j": np.tile([2, 3, 3], (k, 1))}
    dec = _decoder(tp.PAIRS_SCHEMA, fields)
    m = dec(cdr_rows(fields, vals, k)[2])
    assert list(m.distance_m) == [6.0, 7.0, 8.0]
    assert list(m.h_m2) == pytest.approx([-6 / 7, -1.0, -8 / 7], abs=0)
    assert list(m.i) == [1, 1, 2] and list(m.j) == [2, 3, 3]


def test_pairs_ids_past_255_keep_their_value() -> None:
    """A swarm of more than 255 agents (in process): the pair ids are uint16, decoded by
    the independent decoder to the same numbers (uint8 would have wrapped 300 to 44)."""
    k, npair = 2, 3
    fields = tp.pairs_fields(npair, max_id=300)
    assert dict((f[0], f[1]) for f in fields)["i"] == "uint16[3]"
    assert dict((f[0], f[1]) for f in tp.pairs_fields(npair, 255))["i"] == "uint8[3]"
    vals = {"t_s": np.arange(k, dtype=float), "min_distance_m": np.full(k, 1.5),
            "min_h_m2": np.full(k, -0.25), "distance_m": np.ones((k, npair)),
            "h_m2": np.ones((k, npair)), "i": np.tile([1, 256, 299], (k, 1)),
            "j": np.tile([256, 299, 300], (k, 1))}
    m = _decoder(tp.PAIRS_SCHEMA, fields)(cdr_rows(fields, vals, k)[1])
    assert list(m.i) == [1, 256, 299] and list(m.j) == [256, 299, 300]


def test_layout_refuses_padding_and_unknown_types() -> None:
    with pytest.raises(ValueError, match="padding"):
        layout((("a", "uint8", ""), ("b", "float64", "")))
    with pytest.raises(ValueError, match="padding"):
        layout((("a", "uint8[3]", ""), ("b", "uint16", "")))
    assert layout((("a", "uint8[4]", ""), ("b", "uint16", ""))).itemsize == 4 + 4 + 2
    with pytest.raises(ValueError, match="not supported"):
        layout((("a", "string", ""),))
    assert layout(tp.ESTIMATE_FIELDS).itemsize == 4 + 8 * (1 + 9 * 3 + 4)


def test_series_events_onsets_and_recovery() -> None:
    ns = np.arange(6) * 20_000_000
    fb = np.zeros((6, 2), bool)
    fb[2:4, 1] = True  # agent 2 falls back at step 2, recovers at step 4
    al = np.zeros((6, 2), np.uint8)
    al[1:, 0] = int(AgentAlarm.RESIDUAL)
    al[3, 0] |= int(AgentAlarm.DEADLOCK)
    ev = series_events(ns, [1, 2], fb, al, np.zeros((6, 2), bool))
    got = sorted((e.ns, e.level, e.name, e.message) for e in ev)
    assert got == sorted([
        (ns[2], WARNING, "agent/2", "QP degraded: fallback"),
        (ns[4], INFO, "agent/2", "QP recovered"),
        (ns[1], WARNING, "agent/1", "alarm RESIDUAL"),
        (ns[3], WARNING, "agent/1", "alarm DEADLOCK"),
    ])


def test_document_events_sorted_with_safety_alarms() -> None:
    doc = {"scenario": "s", "method": "dcbf", "seed": 1, "run": {"failed_agents": [4]},
           "metrics": {"safety_verdict": "unsafe", "min_distance_m": 0.2, "safety_alarms": [
               {"t_s": 0.04, "assumption": "collision", "agent": 1, "other": 2, "value": 0.2}]}}
    ns = np.arange(5) * 20_000_000
    z = np.zeros((5, 2))
    ev = all_events(doc, ns, [1, 2], z.astype(bool), z.astype(np.uint8), z.astype(bool))
    assert [e.ns for e in ev] == sorted(e.ns for e in ev)
    assert ev[0].message.startswith("start: scenario s")
    assert any(e.ns == 40_000_000 and "collision" in e.message for e in ev)
    assert any("failed agents: [4]" in e.message for e in ev)
    assert ev[-1].message.startswith("end: safety verdict unsafe")


def test_audit_commands_faults_and_failsafes_are_events() -> None:
    """MAVLink commands (modes by name, arming, telemetry requests DEBUG, refusals WARNING),
    Zenoh commands, killed agents and the simulator's failsafes; times clamped to the run;
    malformed records skipped or shown as they are, never an exception."""
    rec = {"vehicle": 2, "link": "gcs", "signed": False, "accepted": True, "reason": "",
           "result": "MAV_RESULT_ACCEPTED"}
    doc = {"metrics": {}, "audit": {"mavlink": [
        {**rec, "t": 0.02, "command": "SET_MODE", "params": [1, 4 << 16 | 6 << 24]},
        {**rec, "t": 0.04, "command": "MAV_CMD_COMPONENT_ARM_DISARM", "params": [0.0, None]},
        {**rec, "t": -1.0, "command": "MAV_CMD_REQUEST_MESSAGE", "params": [33.0]},
        {**rec, "t": 99.0, "command": "MAV_CMD_NAV_LAND", "params": [], "accepted": False,
         "result": "MAV_RESULT_DENIED", "reason": "busy"},
        {**rec, "t": float("nan"), "command": "MAV_CMD_DO_SET_MODE", "params": "junk"},
        "not a record"],
        "zenoh": [{"t": 0.06, "kind": "method", "agent": 3, "fields": {"method": "rcbf"}},
                  {"t": 0.0, "kind": "outage", "agent": 0, "fields": {"duration_s": 0.5}},
                  {"kind": "hold", "fields": None}],
        "mavlink_dropped": 2, "zenoh_dropped": "x"},
        "run": {"killed_agents": [5], "failed_agents": [],
                "simulator": {"summary": "stats: steps=9 failsafes=3 throttled=0"}}}
    ns0, ns1 = 0, 80_000_000
    got = {(e.ns, e.level, e.name, e.message) for e in document_events(doc, ns0, ns1)}
    want = {
        (20_000_000, INFO, "agent/2", "MAVLink set mode LAND: MAV_RESULT_ACCEPTED "
         "[link gcs, unsigned]"),
        (40_000_000, INFO, "agent/2", "MAVLink disarm: MAV_RESULT_ACCEPTED [link gcs, "
         "unsigned]"),
        (ns0, DEBUG, "agent/2", "MAVLink MAV_CMD_REQUEST_MESSAGE: MAV_RESULT_ACCEPTED "
         "[link gcs, unsigned]"),
        (ns1, WARNING, "agent/2", "MAVLink MAV_CMD_NAV_LAND: MAV_RESULT_DENIED (busy) "
         "[link gcs, unsigned]"),
        (ns0, INFO, "agent/2", "MAVLink MAV_CMD_DO_SET_MODE: MAV_RESULT_ACCEPTED "
         "[link gcs, unsigned]"),
        (60_000_000, INFO, "gcs", "command method rcbf to agent 3"),
        (ns0, INFO, "gcs", "command outage 0.5 s to all agents"),
        (ns0, INFO, "gcs", "command hold to all agents"),
        (ns0, WARNING, "run", "audit: 2 commands past the caps not listed"),
        (ns1, WARNING, "run", "fault: agents killed on purpose: [5]"),
        (ns1, WARNING, "run", "vehicle-sim: 3 offboard-loss failsafes"),
    }
    assert want <= got
    assert len(got - want) == 2  # the start and the end


def test_world_entities_of_obstacles_and_geofence() -> None:
    from conftest import ROOT

    from gcs.records.scene import world_entities
    from swarm_common.scenario.model import load_scenario

    world = load_scenario(str(ROOT / "scenarios" / "cube8_obstacles.toml")).world
    upd = SceneUpdate(entities=world_entities(0, world))
    fx = SceneUpdate.get_schema()
    schema = McapSchema(id=1, name=fx.name, encoding=fx.encoding, data=fx.data)
    decoded = ProtobufDecoder().decoder_for("protobuf", schema)(upd.encode())
    ents = {e.id: e for e in decoded.entities}
    kinds = [str(o.kind) for o in world.obstacles]
    ob = ents["obstacles"]
    assert (len(ob.spheres), len(ob.cylinders), len(ob.cubes)) == (
        kinds.count("sphere"), kinds.count("cylinder"), kinds.count("box"))
    sph = [o for o in world.obstacles if str(o.kind) == "sphere"]
    assert ob.spheres[0].size.x == pytest.approx(2 * sph[0].radius_m, abs=1e-12)
    fence = world.geofence
    pts = {(p.x, p.y, p.z) for p in ents["geofence"].lines[0].points}
    corners = {(x, y, z) for x in (fence.min_m[0], fence.max_m[0])
               for y in (fence.min_m[1], fence.max_m[1]) for z in (fence.min_m[2], fence.max_m[2])}
    assert pts == corners  # a box: 12 edges between its 8 corners
    assert len(ents["geofence"].lines[0].points) == 24
