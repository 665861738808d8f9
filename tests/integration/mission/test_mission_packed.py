"""Agents packed per process (``offboard --agents``, ``gcs mission run --processes N``):
a lockstep packed run equals the in-process run as the one-process-per-agent run does."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import CUBE8, ROOT, free_port_offset

from gcs.mission.distributed import recorded_metrics, run_distributed
from gcs.mission.inproc import run_inproc
from gcs.mission.score import lockstep_misses
from swarm_common.jit import CHECK_ENV
from swarm_common.scenario.model import dump_toml, load_scenario

pytestmark = pytest.mark.timeout(240)


def test_lockstep_packed_run_matches_inproc(tmp_path: Path) -> None:
    """cube8 in two daemon processes of four agents: same numbers as in process (float32
    wire rounding only, the tolerances of test_mission_distributed's equality test)."""
    sc = load_scenario(CUBE8)
    dur = 3.0
    ref = run_inproc(sc, "rcbf", duration=dur)
    rec, facts = run_distributed(sc, tmp_path, "rcbf", None, dur, port_offset=free_port_offset(),
                                 show_progress=False, processes=2)
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], dur)
    assert facts["daemon_processes"] == 2
    assert {"offboard-1-4", "offboard-5-8"} <= set(facts["processes"])
    assert len(ser.t) == len(ref.series.t) == int(dur * 50)
    assert m["collisions"] == ref.metrics["collisions"] == 0
    if not lockstep_misses(facts):
        assert abs(m["min_distance_m"] - ref.metrics["min_distance_m"]) < 1e-6
        assert np.array_equal(ser.input_clipped, ref.series.input_clipped)
    _same_as_inproc(facts, ser, ref.series)
    assert facts["failed_agents"] == []
    # every packed agent kept its own MAVLink link and wrote its own .tlog
    for i in sc.ids:
        assert (tmp_path / f"vehicle_{i}.tlog").stat().st_size > 0


def test_in_range_noise_draws_packed_run_matches_inproc(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``[sensing] noise_draws = "in_range"`` on cube8 with a 5.7 m range (pairs come into
    and out of range, so each sensor's draws change in count from step to step): two daemon
    processes give the in-process run's numbers, as with the default draws. Every kernel
    call site of both runs checks its argument types on every call (swarm_common.jit):
    a daemon whose site changed types would raise and fail its agents."""
    monkeypatch.setenv(CHECK_ENV, "1")
    doc = tomllib.loads(Path(CUBE8).read_text())
    doc["formation"]["sensing_range_m"] = 5.7
    doc["controller"]["max_transient_speed_mps"] = 1.15
    doc["sensing"]["noise_draws"] = "in_range"
    path = tmp_path / "cube8_in_range.toml"  # the daemons read the file
    path.write_text(dump_toml(doc))
    sc = load_scenario(path)
    dur = 3.0
    ref = run_inproc(sc, "dcbf", duration=dur)
    out = tmp_path / "run"
    rec, facts = run_distributed(sc, out, "dcbf", None, dur, port_offset=free_port_offset(),
                                 show_progress=False, processes=2)
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], dur)
    assert facts["failed_agents"] == []
    assert len(ser.t) == len(ref.series.t) == int(dur * 50)
    _same_as_inproc(facts, ser, ref.series)


def test_sparse_graph_packed_run_matches_inproc(tmp_path: Path) -> None:
    """grid27_knn (each daemon subscribes to its peers' keys only, offboard.agent.peers)
    in three daemon processes: the in-process runner gives each agent the same peers'
    estimates, so the runs agree (before it did, they parted by 0.11 m within 2 s)."""
    sc = load_scenario(str(ROOT / "scenarios" / "grid27_knn.toml"))
    dur = 2.0
    ref = run_inproc(sc, None, duration=dur)
    # every one of the 27 vehicles' ports claimed, not the first eight's
    rec, facts = run_distributed(sc, tmp_path, None, None, dur,
                                 port_offset=free_port_offset(sc.n),
                                 show_progress=False, processes=3)
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], dur)
    assert facts["failed_agents"] == []
    assert len(ser.t) == len(ref.series.t) == int(dur * sc.run.control_hz)
    assert m["collisions"] == 0
    _same_as_inproc(facts, ser, ref.series)


def _same_as_inproc(facts: dict, ser: Any, ref: Any) -> None:
    """The distributed series equals the in-process one (float32 wire rounding only),
    unless the run reported a lockstep wait it gave up (:func:`lockstep_misses`: the
    simulator's lockstep timeouts, the daemons' lockstep gaps). Equality is promised only
    without them (docs/architecture.md): once seen under double load of the whole suite,
    grid27_knn parted by 2.4e-4 m."""
    missed = lockstep_misses(facts)
    if missed:  # a starved machine: lockstep gave up waiting, and the run said so
        print(f"not compared with the in-process run: {missed[:3]}")
        return
    assert np.max(np.abs(ser.p - ref.p)) < 1e-6
    np.testing.assert_allclose(ser.z1, ref.z1, atol=1e-9, rtol=0)


@pytest.mark.parametrize(
    ("extra", "expect"),
    [
        (["--agents", "3-x"], "--agents '3-x': '3-x' is not an id"),
        (["--agents", "7-3"], "--agents '7-3': '7-3': ids are >= 1"),
        (["--agents", "3-9"], "[9] not agents of the scenario"),
        (["--agents", "1-2", "--mavlink", "udpin:127.0.0.1:14540"], "--mavlink names one"),
        (["--agents", "1-2", "--tlog", "/tmp/x.tlog"], "the path needs {id}"),
    ],
)
def test_offboard_agents_bad_input_one_line(extra: list[str], expect: str) -> None:
    out = subprocess.run([sys.executable, "-m", "offboard.cli", "--scenario", CUBE8, *extra],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert expect in out.stderr.strip().splitlines()[-1]
    assert "Traceback" not in out.stderr


def test_more_processes_than_agents_exits_2_with_one_line() -> None:
    r = subprocess.run([sys.executable, "-m", "gcs.cli", "mission", "run", CUBE8,
                        "--processes", "9", "--duration", "0.1"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines == ["gcs mission run: --processes 9: must be 1..8 (the number of agents)"]
