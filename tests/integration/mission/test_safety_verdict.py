"""No silent break: a run of a safety filter that breaks the truth or an assumption says so
in its log, its metrics and its exit status (3), in process and distributed; a baseline
(``none``) says so in the log and the metrics and exits 0; a safe run exits 0 (issue 40;
docs/metrics.md "Safety verdict", gcs.exit_codes)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, free_port_offset

from gcs.exit_codes import EXIT_OK, EXIT_SAFETY
from swarm_common.scenario.model import dump_toml, load_scenario

pytestmark = pytest.mark.timeout(300)


def fast_start(tmp_path: Path) -> Path:
    """cube8 with one follower (the third agent) starting at 3 m/s toward its neighbour
    above it: 2.2 m apart, closing at 3.6 m/s, outside the safe set at t = 0 (refused at
    load without --allow-unsafe)."""
    data = load_scenario(CUBE8).to_toml_dict()
    data["agent"][2]["velocity"] = [0.0, 0.0, 3.0]
    path = tmp_path / "fast_start.toml"
    path.write_text(dump_toml(data))
    return path


def gcs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=240)


def verdict_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if "safety verdict" in ln]


def test_a_broken_inproc_run_of_dcbf_exits_3_and_says_why(tmp_path: Path) -> None:
    path = fast_start(tmp_path)
    r = gcs("mission", "run", str(path), "--inproc", "--method", "dcbf", "--duration", "2",
            "--allow-unsafe", "--json", "--out", str(tmp_path / "dcbf"))
    assert r.returncode == EXIT_SAFETY, r.stderr[-2000:]
    m = json.loads((tmp_path / "dcbf" / "metrics.json").read_text())["metrics"]
    assert m["safety_verdict"] in ("unsafe", "alarm")
    assert m["safety_alarm_count"] >= 1 and m["safety_alarms"]
    assert json.loads(r.stdout)["metrics"]["safety_verdict"] == m["safety_verdict"]
    (line,) = verdict_lines(r.stderr)
    assert "WARNING" in line and m["safety_verdict"].upper() in line
    # the baseline without a filter breaks too: warned, scored, exit 0
    r = gcs("mission", "run", str(path), "--inproc", "--method", "none", "--duration", "2",
            "--allow-unsafe", "--out", str(tmp_path / "none"))
    assert r.returncode == EXIT_OK, r.stderr[-2000:]
    m = json.loads((tmp_path / "none" / "metrics.json").read_text())["metrics"]
    assert m["safety_verdict"] == "unsafe" and len(verdict_lines(r.stderr)) == 1


def test_a_safe_run_exits_0_with_no_verdict_line(tmp_path: Path) -> None:
    r = gcs("mission", "run", CUBE8, "--inproc", "--method", "dcbf", "--duration", "3",
            "--out", str(tmp_path))
    assert r.returncode == EXIT_OK, r.stderr[-2000:]
    m = json.loads((tmp_path / "metrics.json").read_text())["metrics"]
    assert m["safety_verdict"] == "safe" and m["safety_alarms"] == []
    assert m["own_h_min"] is not None and m["own_h_min"] >= 0.0
    assert verdict_lines(r.stderr) == []


def test_a_broken_distributed_run_exits_3(tmp_path: Path) -> None:
    """The same through real processes (packed), --allow-unsafe passed to the simulator and
    the daemons."""
    path = fast_start(tmp_path)
    r = gcs("mission", "run", str(path), "--method", "dcbf", "--duration", "2",
            "--allow-unsafe", "--processes", "2", "--port-offset", str(free_port_offset()),
            "--out", str(tmp_path / "dist"))
    assert r.returncode == EXIT_SAFETY, r.stderr[-3000:]
    m = json.loads((tmp_path / "dist" / "metrics.json").read_text())["metrics"]
    assert m["safety_verdict"] in ("unsafe", "alarm") and m["safety_alarms"]
    assert len(verdict_lines(r.stderr)) == 1
