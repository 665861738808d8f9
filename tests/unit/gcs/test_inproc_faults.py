"""A scenario's [faults] table in process: not applied, and the log says so (the in-process
runner has no links); no "fault injection on" line from a process that opens no link."""

from __future__ import annotations

import logging

import pytest
from conftest import CUBE8

from gcs.mission.inproc import run_inproc
from swarm_common.scenario.model import load_scenario, with_overrides


def test_faults_in_process_are_named_as_not_applied(caplog: pytest.LogCaptureFixture) -> None:
    sc = with_overrides(load_scenario(CUBE8), faults={"mavlink": {"drop": 0.2}})
    assert sc.faults.active
    with caplog.at_level(logging.INFO):
        res = run_inproc(sc, "dcbf", duration=0.1)
    text = caplog.text
    assert "[faults] table is NOT applied" in text
    assert "fault injection on" not in text
    plain = run_inproc(load_scenario(CUBE8), "dcbf", duration=0.1)
    assert res.metrics["min_distance_m"] == plain.metrics["min_distance_m"]  # nothing faulted
