"""Command lines given a bad scenario or flag: non-zero exit and one stderr line."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import CUBE8, ROOT
from scenario_variants import CASES, scenario_variant


@pytest.mark.parametrize(("old", "new", "expect"), CASES[:3])
def test_cli_exits_nonzero_with_one_line(tmp_path, old, new, expect):
    p = scenario_variant(tmp_path, old, new)
    r = subprocess.run(
        [sys.executable, "-m", "vehicle_sim.cli", "--scenario", str(p), "--no-zenoh"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    for e in expect:
        assert e in lines[0]


def test_cli_bad_vehicles_count(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "vehicle_sim.cli", "--scenario", CUBE8, "--vehicles", "9"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode != 0
    assert r.stderr.strip().count("\n") == 0 and "--vehicles" in r.stderr


def _gcs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def test_infeasible_scenario_exits_2_unless_allowed(tmp_path):
    """cube8's trajectory at 0.4 Hz needs more acceleration than the input set allows: one
    line naming the key and the flag, exit 2; with --allow-infeasible it runs (a warning)."""
    p = scenario_variant(tmp_path, "frequency_hz = 0.2", "frequency_hz = 0.4")
    r = _gcs("mission", "run", str(p), "--inproc", "--duration", "0.2")
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "leader_trajectory.frequency_hz = 0.4" in lines[0]
    assert "--allow-infeasible" in lines[0]
    r = _gcs("mission", "run", str(p), "--inproc", "--duration", "0.2", "--json",
             "--allow-infeasible")
    assert r.returncode == 0, r.stderr
    assert "WARNING" in r.stderr and "leader_trajectory.frequency_hz = 0.4" in r.stderr
    assert r.stdout.strip().startswith("{")
