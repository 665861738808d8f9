"""``gcs mission sweep`` as a real subprocess: runs.csv, summary.md, crashed runs. Bad input
ends before anything starts: ``gcs``'s ``main`` in this process (:func:`cli_inproc.run_cli`)."""

from __future__ import annotations

import csv
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_inproc import run_cli
from conftest import CUBE8, ROOT

from gcs.report.sweep import CSV_COLUMNS
from gcs.sweep.jobs import Job
from gcs.sweep.local import run_sweep

pytestmark = pytest.mark.timeout(240)
GCS = [sys.executable, "-m", "gcs.cli"]


def _sweep(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*GCS, "mission", "sweep", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=200)


def test_sweep_writes_rows_and_summary(tmp_path: Path) -> None:
    r = _sweep(CUBE8, "--seeds", "1-2", "--methods", "rcbf,none", "--jobs", "2",
               "--duration", "3", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    with (tmp_path / "runs.csv").open() as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames or ()) == CSV_COLUMNS
        rows = list(reader)
    assert sorted((x["method"], int(x["seed"])) for x in rows) == [
        ("none", 1), ("none", 2), ("rcbf", 1), ("rcbf", 2)]
    assert all(x["status"] == "ok" and x["scenario"] == "cube8" for x in rows)
    for x in rows:
        for k in ("min_distance_m", "h_min", "barrier_violation_steps", "collisions",
                  "input_clipped_steps", "min_distance_formation_m"):
            assert math.isfinite(float(x[k])), (k, x[k])
        # a 3 s run never reaches the 20 s formation deadline: no tracking window
        assert x["tracking_rms_m"] == "" and x["min_distance_mission_m"] == ""
    none = [x for x in rows if x["method"] == "none"]
    assert all(int(x["barrier_violation_steps"]) > 0 and float(x["h_min"]) < 0 for x in none)
    summary = (tmp_path / "summary.md").read_text()
    assert "| cube8 | none | 2 (0) |" in summary and "| cube8 | rcbf | 2 (0) |" in summary
    assert (tmp_path / "summary.png").read_bytes()[:4] == b"\x89PNG"
    assert "4/4 runs, 0 failed, 0 s left" in r.stderr  # the progress display


def test_crashed_run_is_a_row_not_lost(tmp_path: Path) -> None:
    bad = tmp_path / "gone.toml"  # removed after validation: the worker's load fails
    jobs = [Job(str(bad), "gone", "rcbf", 1, 1.0), Job(CUBE8, "cube8", "none", 1, 0.2)]
    rows = {r["scenario"]: r for r in run_sweep(jobs, 2, show_progress=False)}
    assert rows["gone"]["status"] == "crashed" and "gone.toml" in rows["gone"]["error"]
    assert rows["cube8"]["status"] == "ok" and float(rows["cube8"]["min_distance_m"]) > 0


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--seeds", "5-1"], "--seeds"),
        (["--seeds", "-3"], "--seeds"),
        (["--seeds", "a,b"], "--seeds"),
        (["--jobs", "0"], "--jobs"),
        (["--methods", "rcbf,magic"], "magic"),
        (["--duration", "-1"], "--duration"),
        (["--cluster", "nonsense"], "--cluster"),
        (["--cluster", "tcp://host"], "--cluster"),
    ],
)
def test_bad_input_exits_2_with_one_line(args: list[str], needle: str, tmp_path: Path) -> None:
    r = run_cli("gcs", ["mission", "sweep", CUBE8, *args, "--out", str(tmp_path / "o")])
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gcs mission sweep:") and needle in lines[0]
    assert not (tmp_path / "o").exists()


def test_unknown_scenario_exits_2(tmp_path: Path) -> None:
    r = run_cli("gcs", ["mission", "sweep", str(tmp_path / "nope.toml"), "--seeds", "1",
                        "--out", str(tmp_path / "o")])
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "nope.toml" in lines[0]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}").exists() and "Z" not in _state(pid)


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return ""


def _children(pid: int) -> list[int]:
    """The child pids of every thread of ``pid``; a thread that exits between the listing
    and the read is skipped (its children, if any, pass to another thread of the process)."""
    out: list[int] = []
    try:
        tasks = list(Path(f"/proc/{pid}/task").iterdir())
    except OSError:  # the process itself ended: the caller's checks say so
        return out
    for task in tasks:
        try:
            kids = (task / "children").read_text().split()
        except OSError:  # the thread ended meanwhile
            continue
        out += [int(k) for k in kids]
    return out


def test_sigterm_stops_workers_and_keeps_finished_runs(tmp_path: Path) -> None:
    """SIGTERM mid-sweep: exit 143, no worker left, the finished runs written."""
    proc = subprocess.Popen(
        [*GCS, "mission", "sweep", CUBE8, "--seeds", "1-40", "--methods", "none",
         "--jobs", "2", "--duration", "1", "--out", str(tmp_path)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    workers: list[int] = []
    err = proc.stderr
    assert err is not None
    for line in err:  # progress lines "[sweep 40 runs] ... N/40 runs, 0 crashed"
        workers = _children(proc.pid) or workers
        m = re.search(r"(\d+)/40 runs", line)
        if m and int(m.group(1)) >= 1:
            break
    assert proc.poll() is None, "the sweep ended before it could be interrupted"
    proc.send_signal(signal.SIGTERM)
    _, err_text = proc.communicate(timeout=60)
    assert proc.returncode == 143, err_text
    deadline = time.monotonic() + 10
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert workers and not any(_alive(w) for w in workers)
    with (tmp_path / "runs.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert 1 <= len(rows) < 40 and all(r["status"] == "ok" for r in rows)
