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
