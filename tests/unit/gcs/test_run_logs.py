"""The lockstep gaps a run's facts report (gcs.mission.run_logs, gcs.mission.score): read
from the lines the daemon's own code logs when it gives up a wait."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gcs.mission.run_logs import GAPS_KEPT, lockstep_gaps
from gcs.mission.score import lockstep_misses
from offboard.daemon.drivers import LockstepDriver
from offboard.daemon.runner_loss import RunnerLoss
from offboard.daemon.sensing_source import SwarmSensing
from swarm_common import wire
from swarm_common.enums import SensingSource


class _SilentSwarm:
    """A swarm bus on which nothing ever arrives: every wait times out at once."""

    def __init__(self) -> None:
        self.estimates: dict[int, dict[int, wire.Estimate]] = {}
        self.truth: dict[int, Any] = {}
        self.odometry: dict[int, dict[int, Any]] = {}
        self.latest_odometry: dict[int, Any] = {}

    def wait(self, predicate: Any, timeout: float) -> bool:
        return False

    def estimates_at(self, step: int) -> dict[int, wire.Estimate]:
        return {}

    def publish_odometry(self, odo: Any) -> None:
        pass


def _daemon_lines(agent: int, caplog: pytest.LogCaptureFixture) -> str:
    """What a lockstep daemon of ``agent`` logs when neighbours 2 and 5 stay silent at
    step 7, then its truth of step 9 and neighbour 3's odometry at step 4 never come."""
    swarm = _SilentSwarm()
    index_of = {1: 0, 2: 1, 3: 2, 4: 3, 5: 4}
    driver = LockstepDriver(swarm, agent, [2, 5], index_of, None,  # type: ignore[arg-type]
                            solo=False, startup_timeout=1.0, neighbour_timeout=0.01,
                            stopped=lambda: False)
    sensing = SwarmSensing(
        SensingSource.TRUTH, [1, 2, 3], agent, swarm, RunnerLoss(50),  # type: ignore[arg-type]
        lockstep=True, solo=False, truth_timeout=0.01, neighbour_timeout=0.01,
        startup_timeout=1.0, sensing_range_m=5.0, stopped=lambda: False, on_lost=lambda: None)
    with caplog.at_level(logging.WARNING):
        assert driver.neighbours(7) == {}
        assert driver.neighbours(8) == {}  # lost ones are not waited for, nor said again
        assert sensing.for_step(9) is None
        sensing.source = SensingSource.ODOMETRY
        sensing.own = wire.Odometry(agent, 4, 0.08, np.zeros(3), np.zeros(3))
        sensing.for_step(4)
    return "\n".join(f"2026-12-01 00:00:00 WARNING {r.getMessage()}" for r in caplog.records)


def test_the_daemons_own_lines_become_the_runs_gaps(tmp_path: Path,
                                                    caplog: pytest.LogCaptureFixture) -> None:
    (tmp_path / "offboard-1.log").write_text(_daemon_lines(1, caplog) + "\n")
    caplog.clear()
    (tmp_path / "offboard-4-6.log").write_text(_daemon_lines(4, caplog) + "\nINFO other\n")
    (tmp_path / "vehicle-sim.log").write_text("agent 9: neighbour 1 silent at step 1: lost\n")
    count, first = lockstep_gaps(tmp_path)
    assert count == 11  # agent 1: 2 + 1 + 2 (ids 1-3); agent 4: 2 + 1 + 3
    assert first[:4] == [
        {"kind": "odometry", "agent": 1, "neighbour": 2, "step": 4},
        {"kind": "odometry", "agent": 1, "neighbour": 3, "step": 4},
        {"kind": "odometry", "agent": 4, "neighbour": 1, "step": 4},
        {"kind": "odometry", "agent": 4, "neighbour": 2, "step": 4},
    ]
    assert {"kind": "estimate", "agent": 4, "neighbour": 5, "step": 7} in first
    assert first[-1] == {"kind": "truth", "agent": 4, "neighbour": 0, "step": 9}
    misses = lockstep_misses({"simulator": {"lockstep_timeouts": 0},
                              "lockstep_gaps": {"count": count, "first": first}})
    assert misses[0] == "daemons: 11 lockstep gap(s)"
    assert "agent 4: no truth at step 9" in misses
    assert "agent 1: no estimate of 5 at step 7" in misses


def test_a_clean_run_reports_no_miss_and_long_lists_are_cut(tmp_path: Path) -> None:
    assert lockstep_gaps(tmp_path) == (0, [])
    assert lockstep_misses({}) == []
    assert lockstep_misses({"simulator": {"lockstep_timeouts": 0},
                            "lockstep_gaps": {"count": 0, "first": []}}) == []
    assert lockstep_misses({"simulator": {"lockstep_timeouts": 3}}) == [
        "simulator: 3 lockstep timeout(s)"]
    lines = [f"agent 2: no truth for step {k}" for k in range(GAPS_KEPT + 50, 0, -1)]
    (tmp_path / "offboard-2.log").write_text("\n".join(lines))
    count, first = lockstep_gaps(tmp_path)
    assert count == GAPS_KEPT + 50 and len(first) == GAPS_KEPT
    assert [g["step"] for g in first] == list(range(1, GAPS_KEPT + 1))


def test_the_cli_warns_with_the_gaps_and_names_a_known_cause(
        caplog: pytest.LogCaptureFixture) -> None:
    from gcs.mission.run_cli import warn_misses

    gaps = {"count": 1, "first": [{"kind": "estimate", "agent": 3, "neighbour": 6,
                                   "step": 25}]}
    with caplog.at_level(logging.WARNING):
        warn_misses({"run": {"failed_agents": [], "lockstep_gaps": {"count": 0}}})
        assert caplog.records == []
        warn_misses({"run": {"failed_agents": [], "lockstep_gaps": gaps}})
        warn_misses({"run": {"failed_agents": [6], "lockstep_gaps": gaps,
                             "simulator": {"lockstep_timeouts": 2}}})
    first, second = (r.getMessage() for r in caplog.records)
    assert "agent 3: no estimate of 6 at step 25" in first
    assert "may differ from the in-process run" in first and "too slow" in first
    assert "simulator: 2 lockstep timeout(s)" in second and "dead: agent 6's daemon" in second


def test_spans_out_of_offboard_stay_within_the_run() -> None:
    """A vehicle's spans out of OFFBOARD count from its first entry on, a span open at the
    run's end closes there, and a mode change logged after the end (the shutdown's
    failsafe) is not the run's: no span starts after the end or runs past it."""
    from gcs.mission.run_logs import longest_out_of_offboard, out_of_offboard_spans

    log = "\n".join([
        "t=0.50 vehicle 1: mode POSCTL -> OFFBOARD",
        "t=0.60 vehicle 2: mode POSCTL -> OFFBOARD",
        "t=0.70 vehicle 3: mode POSCTL -> OFFBOARD",
        "t=3.00 vehicle 1: mode OFFBOARD -> HOLD",
        "t=4.25 vehicle 1: mode HOLD -> OFFBOARD",
        "t=9.00 vehicle 2: mode OFFBOARD -> HOLD",
        "t=10.50 vehicle 2: mode HOLD -> OFFBOARD",  # back after the end: clipped
        "t=11.00 vehicle 3: mode OFFBOARD -> HOLD",  # the shutdown: not the run's
    ])
    spans = out_of_offboard_spans(log, 10.0)
    assert spans == {1: [(3.0, 4.25)], 2: [(9.0, 10.0)]}
    assert longest_out_of_offboard(log, 10.0) == {1: 1.25, 2: 1.0}
