"""The run's audit trail in metrics.json (gcs.mission.audit; docs/security.md, "Audit
trail"): its shape, the counts, the recorder's Zenoh command records."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from gcs.mission.audit import (
    MISSION_TEXT_KEEP,
    ZENOH_CAP,
    audit_document,
    counts,
    zenoh_record,
)
from gcs.mission.distributed import with_audit
from gcs.mission.inproc import MissionResult
from gcs.mission.recorder import Recorder
from gcs.report.metrics import Series
from swarm_common import wire
from swarm_common.scenario.model import load_scenario

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
AUDIT_KEYS = {"mavlink", "zenoh", "counts", "mavlink_cap_per_vehicle", "mavlink_dropped",
              "mavlink_dropped_per_vehicle", "zenoh_cap", "zenoh_dropped"}


def _mav(cmd: str, result: str, t: float = 1.0) -> dict[str, Any]:
    return {"t": t, "vehicle": 1, "command": cmd, "result": result}


def test_zenoh_record_fields_and_a_long_mission_cut() -> None:
    r = zenoh_record(2.5, "swarm/s/cmd/live", wire.Command(kind="live", agent=3, at_s=4.0,
                                                           velocity=(1.0, -2.0, 0.5)))
    assert (r["t"], r["key"], r["kind"], r["agent"]) == (2.5, "swarm/s/cmd/live", "live", 3)
    assert r["fields"]["at_s"] == 4.0 and r["fields"]["velocity"] == [1.0, -2.0, 0.5]
    assert "kind" not in r["fields"] and "agent" not in r["fields"]
    text = "x" * (MISSION_TEXT_KEEP * 3)
    m = zenoh_record(0.0, "k", wire.Command(kind="mission", mission=text))
    assert len(m["fields"]["mission"]) == MISSION_TEXT_KEEP
    assert m["fields"]["mission_chars"] == MISSION_TEXT_KEEP * 3
    json.dumps(m, allow_nan=False)


def test_counts_per_command_and_result() -> None:
    mav = [_mav("PARAM_SET", "ACCEPTED"), _mav("PARAM_SET", "ACCEPTED"),
           _mav("PARAM_SET", "MAV_PARAM_ERROR_DOES_NOT_EXIST"),
           _mav("MAV_CMD_DO_SET_MODE", "MAV_RESULT_DENIED")]
    zen = [zenoh_record(1.0, "k", wire.Command(kind="land")) for _ in range(3)]
    assert counts(mav, zen) == {
        "MAV_CMD_DO_SET_MODE": {"MAV_RESULT_DENIED": 1},
        "PARAM_SET": {"ACCEPTED": 2, "MAV_PARAM_ERROR_DOES_NOT_EXIST": 1},
        "zenoh:land": {"seen": 3},
    }


def test_audit_document_shape_with_and_without_a_simulator() -> None:
    sim = {"records": [_mav("SET_MODE", "MAV_RESULT_ACCEPTED")], "cap_per_vehicle": 5000,
           "dropped": 4, "dropped_per_vehicle": {"3": 4}}
    doc = audit_document(sim, [], zenoh_dropped=2)
    assert set(doc) == AUDIT_KEYS
    assert doc["mavlink"] == sim["records"] and doc["mavlink_dropped"] == 4
    assert doc["mavlink_dropped_per_vehicle"] == {"3": 4} and doc["zenoh_dropped"] == 2
    assert doc["zenoh_cap"] == ZENOH_CAP
    bare = audit_document(None, [])
    assert set(bare) == AUDIT_KEYS and bare["mavlink"] == [] and bare["counts"] == {}


def test_distributed_document_gets_a_top_level_audit() -> None:
    rec = SimpleNamespace(commands=[zenoh_record(1.0, "k", wire.Command(kind="hold"))],
                          commands_dropped=0)
    full = audit_document({"records": [_mav("PARAM_SET", "ACCEPTED")]}, rec.commands)
    doc: dict[str, Any] = {"metrics": {}, "run": {"audit": full, "wall_s": 1.0}}
    with_audit(doc, rec)  # type: ignore[arg-type]
    assert doc["audit"] is full and "audit" not in doc["run"] and doc["run"]["wall_s"] == 1.0
    early: dict[str, Any] = {"metrics": {}, "run": {"aborted": True}}
    with_audit(early, rec)  # type: ignore[arg-type]
    assert early["audit"]["mavlink"] == [] and early["audit"]["zenoh"] == rec.commands


def test_inproc_document_has_the_same_audit_shape() -> None:
    res = MissionResult("s", "dcbf", 1, {}, Series.__new__(Series))
    doc = res.document()
    assert set(doc["audit"]) == AUDIT_KEYS and doc["audit"]["zenoh"] == []


class _Sub:
    """A subscriber channel holding ``samples`` (key, payload bytes)."""

    def __init__(self, samples: list[tuple[str, bytes]]) -> None:
        self.samples = [SimpleNamespace(key_expr=k, payload=SimpleNamespace(to_bytes=lambda b=b: b))
                        for k, b in samples]

    def try_recv(self) -> Any:
        return self.samples.pop(0) if self.samples else None


def test_recorder_keeps_commands_at_the_newest_truth_time_and_caps_them() -> None:
    sc = load_scenario(CUBE8)
    rec = Recorder(sc, steps=10)
    rec.max_step, rec.t[3] = 3, 0.06
    land = wire.encode(wire.Command(kind="land", at_s=5.0))
    rec._subs = [_Sub([("swarm/cube8/cmd/land", land), ("swarm/cube8/cmd/x", b"\x00junk")])]
    rec.drain()
    assert rec.dropped == 1  # the payload that does not decode
    assert len(rec.commands) == 1
    c = rec.commands[0]
    assert (c["t"], c["key"], c["kind"], c["fields"]["at_s"]) == (0.06, "swarm/cube8/cmd/land",
                                                                  "land", 5.0)
    rec.commands = [c] * ZENOH_CAP
    rec._subs = [_Sub([("k", land)] * 3)]
    rec.drain()
    assert len(rec.commands) == ZENOH_CAP and rec.commands_dropped == 3
    assert np.isnan(rec.t[4])  # nothing else touched
