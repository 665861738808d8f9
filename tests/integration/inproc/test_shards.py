"""The agents of an in-process run stepped in worker processes
(gcs.mission.agents.shards): the same run bit for bit as one process, a dead worker fails
the run in one line, and the shards cover the swarm."""

from __future__ import annotations

import json
import os
import socket
import subprocess
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import ROOT, load_shipped

from gcs.cli import main as gcs_main
from gcs.mission.agents import MAX_WORKERS, shards
from gcs.mission.agents.shards import AgentShards, ShardError, serve_shard, shard_bounds
from gcs.mission.compare_cli import METHODS
from gcs.mission.inproc import MissionResult, run_inproc
from swarm_common.enums import Role


def _same_run(a: MissionResult, b: MissionResult) -> None:
    """Every series and metric of two runs equal, but the QP's and the run's wall times."""
    da, db = a.series.as_dict(), b.series.as_dict()
    assert da.keys() == db.keys()
    for key in da:
        if key != "solve_us":
            assert np.array_equal(da[key], db[key], equal_nan=True), key
    skip = ("wall_s", "realtime_factor")
    assert ({k: v for k, v in a.metrics.items() if k not in skip}
            == {k: v for k, v in b.metrics.items() if k not in skip})
    assert a.gains == b.gains and a.collision_pairs == b.collision_pairs


@pytest.mark.parametrize(("name", "workers", "land_at"), [
    ("cube8_rogue", 3, 4.0),  # a rogue agent, a link outage at 5 s, a land-all at 4 s
    ("cube8_delay50", 2, None),  # estimates two periods late
])
def test_workers_fly_the_same_bits(name: str, workers: int, land_at: float | None) -> None:
    sc = load_shipped(ROOT / "scenarios" / f"{name}.toml")
    one = run_inproc(sc, "dcbf", duration=6.0, land_at=land_at)
    many = run_inproc(sc, "dcbf", duration=6.0, land_at=land_at, workers=workers)
    _same_run(one, many)
    assert one.metrics["collisions"] == 0 and one.series.h_min.shape == (300, sc.n)


def test_a_dead_worker_fails_the_run_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker killed mid-run: the run raises ShardError naming it, and no worker is
    left running."""
    started: list[subprocess.Popen[bytes]] = []
    step = AgentShards.step

    def killing(self: AgentShards, k: int, *rest: Any) -> Any:
        if k == 20:
            started.extend(self._procs)
            self._procs[0].kill()
            self._procs[0].wait()
        return step(self, k, *rest)

    monkeypatch.setattr(AgentShards, "step", killing)
    sc = load_shipped(ROOT / "scenarios" / "cube8.toml")
    with pytest.raises(ShardError, match=r"agent worker agents \d+-\d+ died") as err:
        run_inproc(sc, "dcbf", duration=2.0, workers=3)
    assert "\n" not in str(err.value)
    assert len(started) == 2 and all(p.poll() is not None for p in started)


def test_a_worker_that_dies_at_its_start_fails_the_run_in_one_line(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shards, "WORKER_CODE", "import os; os._exit(3)")
    sc = load_shipped(ROOT / "scenarios" / "cube8.toml")
    with pytest.raises(ShardError, match=r"^agent worker agents \d+-7 died \(exit 3\)$"):
        run_inproc(sc, "dcbf", duration=0.2, workers=2)


def test_the_gain_report_comes_from_a_worker_when_the_run_holds_no_follower() -> None:
    """The run's own shard is one leader: the first follower's gain report is asked of a
    worker, and it is the report a run in one process gives."""
    from offboard.estimation.bearing import formation_from_scenario

    sc = load_shipped(ROOT / "scenarios" / "cube8.toml")
    form = formation_from_scenario(sc)
    assert sc.agents[0].role is Role.LEADER
    shards_ = AgentShards(sc, "dcbf", 1, form, [(0, 1), (1, sc.n)])
    try:
        assert shards_.local.gains() == []
        got = shards_.gains()
    finally:
        shards_.close()
    local = shards.agent_steppers(sc, "dcbf", 1, form, 1)
    assert got == local.gains() and len(got) > 0


def test_the_cli_says_a_dead_worker_in_one_line_and_exits_1(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The one line on stderr, exit 1, and with `--foxglove` the same line said to the
    live view as the run stops."""
    from gcs.records.live import LiveView

    step = AgentShards.step
    said: list[str] = []

    def killing(self: AgentShards, k: int, *rest: Any) -> Any:
        if k == 5:
            self._procs[0].kill()
            self._procs[0].wait()
        return step(self, k, *rest)

    monkeypatch.setattr(AgentShards, "step", killing)
    monkeypatch.setattr(LiveView, "fail", lambda self, why: said.append(why))
    rc = gcs_main(["mission", "run", str(ROOT / "scenarios" / "cube8.toml"), "--inproc",
                   "--duration", "1", "--workers", "2", "--foxglove", "--foxglove-port", "0"])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert rc == 1 and last.startswith("gcs mission run: agent worker agents ")
    assert last.endswith("died (exit -9)"), last
    assert said == [last.removeprefix("gcs mission run: ")]


def test_compare_reports_a_method_whose_worker_died(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    """`mission compare --inproc`: the first method's worker is killed; that method is
    said in one line and marked in the report, the others run, and the exit is 1."""
    step = AgentShards.step
    killed: list[str] = []

    def killing(self: AgentShards, k: int, *rest: Any) -> Any:
        if k == 5 and not killed:
            killed.append("once")
            self._procs[0].kill()
            self._procs[0].wait()
        return step(self, k, *rest)

    monkeypatch.setattr(AgentShards, "step", killing)
    out = tmp_path / "cmp"
    rc = gcs_main(["mission", "compare", str(ROOT / "scenarios" / "cube8.toml"), "--inproc",
                   "--duration", "0.4", "--workers", "2", "--out", str(out)])
    err = [ln for ln in capsys.readouterr().err.splitlines()
           if ln.startswith("gcs mission compare:")]
    assert rc == 1 and len(err) == 1, err
    assert err[0].startswith(f"gcs mission compare: {METHODS[0]}: agent worker agents ")
    assert err[0].endswith("died (exit -9)"), err[0]
    assert not (out / METHODS[0]).exists()
    assert all((out / m / "metrics.json").is_file() for m in METHODS[1:])
    assert "did not finish" in (out / "report.md").read_text()


def test_a_worker_reports_its_error_and_stops() -> None:
    """A worker whose set-up fails answers with the error's line and its traceback."""
    mine, theirs = socket.socketpair()
    with Connection(mine.detach()) as run, Connection(theirs.detach()) as worker:
        run.send(("not", "a", "set-up"))
        serve_shard(worker)  # returns after its answer
        kind, line, trace = run.recv()
    assert kind == "error" and line.startswith("ValueError: ") and "Traceback" in trace


def test_the_shards_cover_the_swarm_in_order() -> None:
    sc = load_shipped(ROOT / "scenarios" / "grid27_knn.toml")
    leaders = {i for i, a in enumerate(sc.agents) if a.role == "leader"}
    for workers in (1, 2, 3, 5, 27, 40):
        bounds = shard_bounds(sc, workers)
        assert bounds[0][0] == 0 and bounds[-1][1] == sc.n
        assert all(hi > lo for lo, hi in bounds)
        assert all(a[1] == b[0] for a, b in zip(bounds, bounds[1:], strict=False))
        assert len(bounds) <= min(workers, sc.n)
        followers = [sum(1 for i in range(lo, hi) if i not in leaders) for lo, hi in bounds]
        if workers <= 3:  # as many as asked, as even as whole agents allow
            assert len(bounds) == workers
            assert max(followers) - min(followers) <= 2, (workers, followers)


def test_workers_outside_the_range_are_refused() -> None:
    sc = load_shipped(ROOT / "scenarios" / "cube8.toml")
    for bad in (0, 65):
        with pytest.raises(ValueError, match="workers"):
            run_inproc(sc, "dcbf", duration=0.1, workers=bad)
    assert MAX_WORKERS == 64


@pytest.mark.parametrize(("flags", "says"), [
    (["--workers", "2"], "--workers is for --inproc"),
    (["--workers", "1"], "--workers is for --inproc"),
    (["--inproc", "--workers", "0"], "--workers"),
    (["--inproc", "--workers", "65"], "--workers"),
    (["--inproc", "--workers", "two"], "--workers"),
])
def test_the_cli_refuses_workers_in_one_line(flags: list[str], says: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    try:
        rc = gcs_main(["mission", "run", str(ROOT / "scenarios" / "cube8.toml"), *flags])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and says in err[0], err


def test_compare_refuses_workers_without_inproc(capsys: pytest.CaptureFixture[str],
                                               tmp_path: Path) -> None:
    """As `mission run`: a distributed comparison has no workers; refused before any run."""
    try:
        rc = gcs_main(["mission", "compare", str(ROOT / "scenarios" / "cube8.toml"),
                       "--workers", "2", "--out", str(tmp_path / "cmp")])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--workers is for --inproc" in err[0], err
    assert not (tmp_path / "cmp").exists()


def test_auto_shares_only_a_large_swarm() -> None:
    assert shards.auto_workers(shards.AUTO_MIN_AGENTS - 1) == 1
    many = shards.auto_workers(1024)
    assert 1 <= many <= MAX_WORKERS and many == min(len(os.sched_getaffinity(0)), 64)
    assert shards.auto_workers(shards.AUTO_MIN_AGENTS) == min(many, shards.AUTO_MIN_AGENTS)


def test_the_cli_flies_the_same_run_with_workers(capsys: pytest.CaptureFixture[str]) -> None:
    """gcs mission run --inproc --json on grid64 (auto's size) with 1 and 2 processes:
    the same metrics but the wall time."""
    docs = []
    for workers in ("1", "2"):
        rc = gcs_main(["mission", "run", str(ROOT / "scenarios" / "grid64.toml"), "--inproc",
                       "--duration", "0.4", "--json", "--workers", workers])
        out = capsys.readouterr().out
        assert rc == 0, out
        doc = json.loads(out.strip().splitlines()[-1])
        for key in ("wall_s", "realtime_factor"):
            doc["metrics"].pop(key)
        docs.append(doc)
    assert docs[0] == docs[1] and docs[0]["metrics"]["collisions"] == 0
