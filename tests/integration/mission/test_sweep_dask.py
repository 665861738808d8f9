"""``gcs mission sweep --cluster``: a real Dask scheduler and two workers on 127.0.0.1.

One worker is SIGKILLed (with its nanny) once the first rows have arrived; the sweep must
still end with every run once, the table equal row for row (all but the wall-time columns)
to a local ``--jobs 2`` sweep of the same grid. Then ``--resume`` on the cluster runs only
the rows missing from runs.csv. Every process started here is killed in ``finally``.
"""

from __future__ import annotations

import csv
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import IO

import pytest
from conftest import CUBE8, ROOT

pytestmark = [pytest.mark.timeout(600), pytest.mark.slow]
GCS = [sys.executable, "-m", "gcs.cli"]
GRID = [CUBE8, "--seeds", "1-3", "--methods", "rcbf,none", "--duration", "2"]
WALL_COLUMNS = ("wall_s", "realtime_factor")  # the only cells that differ between runs


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(args: list[str], log: IO[bytes]) -> subprocess.Popen[bytes]:
    """A process in its own session, so that killing its group takes its children too."""
    return subprocess.Popen(args, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)


def _kill_group(proc: subprocess.Popen[bytes] | subprocess.Popen[str]) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


def _table(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return [{k: v for k, v in r.items() if k not in WALL_COLUMNS} for r in csv.DictReader(fh)]


def _wait_for_workers(addr: str, n: int, timeout_s: float) -> None:
    from distributed import Client

    with Client(addr, timeout=timeout_s) as client:
        client.wait_for_workers(n, timeout=timeout_s)


def test_cluster_sweep_survives_a_killed_worker_and_equals_local(tmp_path: Path) -> None:
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    procs: list[subprocess.Popen[bytes]] = []
    logs = [(tmp_path / f"{name}.log").open("wb") for name in ("scheduler", "w1", "w2")]
    sweep: subprocess.Popen[str] | None = None
    try:
        procs.append(_start([sys.executable, "-m", "distributed.cli.dask_scheduler",
                             "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                            logs[0]))
        for log in logs[1:]:
            procs.append(_start([sys.executable, "-m", "distributed.cli.dask_worker", addr,
                                 "--nworkers", "1", "--nthreads", "1", "--no-dashboard"], log))
        _wait_for_workers(addr, 2, timeout_s=120)

        out = tmp_path / "cluster"
        sweep = subprocess.Popen([*GCS, "mission", "sweep", *GRID, "--cluster", addr,
                                  "--out", str(out)], cwd=ROOT, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.PIPE, text=True)
        err = sweep.stderr
        assert err is not None
        seen: list[str] = []
        for line in err:  # progress "[sweep 6 runs] ... N/6 runs, F failed, ... left"
            seen.append(line)
            m = re.search(r"(\d+)/6 runs", line)
            if m and int(m.group(1)) >= 1:
                # 5 runs were still to come when this line was written: the kill is mid-sweep
                assert int(m.group(1)) < 6
                _kill_group(procs[1])
                break
        rest = err.read()
        assert sweep.wait(timeout=400) == 0, "".join(seen) + rest
        assert procs[1].poll() is not None and procs[2].poll() is None

        local = tmp_path / "local"
        r = subprocess.run([*GCS, "mission", "sweep", *GRID, "--jobs", "2", "--out", str(local)],
                           cwd=ROOT, capture_output=True, text=True, timeout=400)
        assert r.returncode == 0, r.stderr
        want = _table(local / "runs.csv")
        assert len(want) == 6 and all(x["status"] == "ok" for x in want)
        assert _table(out / "runs.csv") == want  # every run once, the same values, same order
        assert "| cube8 | rcbf | 3 (0) |" in (out / "summary.md").read_text()

        # --resume on the cluster: keep 3 rows, run only the 3 missing ones
        lines = (out / "runs.csv").read_text().splitlines(keepends=True)
        (out / "runs.csv").write_text("".join(lines[:4]))
        r = subprocess.run([*GCS, "mission", "sweep", *GRID, "--cluster", addr, "--resume",
                            "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                           timeout=400)
        assert r.returncode == 0, r.stderr
        assert "[sweep 3 runs]" in r.stderr and "3/3 runs, 0 failed" in r.stderr
        assert _table(out / "runs.csv") == want
    finally:
        if sweep is not None and sweep.poll() is None:
            sweep.kill()
            sweep.wait(timeout=30)
        for p in reversed(procs):
            _kill_group(p)
        for log in logs:
            log.close()


def test_unreachable_cluster_exits_2_with_one_line(tmp_path: Path) -> None:
    addr = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    t0 = time.monotonic()
    r = subprocess.run([*GCS, "mission", "sweep", CUBE8, "--seeds", "1", "--cluster", addr,
                        "--out", str(tmp_path / "o")], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    took = time.monotonic() - t0
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gcs mission sweep: --cluster ")
    assert addr in lines[0] and not (tmp_path / "o").exists()
    assert took < 60, took  # connect timeout 5 s, plus the start of Python on a loaded machine
