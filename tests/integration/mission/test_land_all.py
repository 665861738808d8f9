"""Coordinated land-all of the stacked cube (docs/lifecycle.md): the CLI's ``--land-at``."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, free_port_offset  # noqa: E402

from gcs.exit_codes import EXIT_OK, EXIT_SAFETY
from gcs.mission.distributed import recorded_metrics, run_distributed
from gcs.mission.inproc import run_inproc
from gcs.mission.score import lockstep_misses
from offboard.agent.landing import landing_plan
from swarm_common.scenario.model import load_scenario

CUBE8 = ROOT / "scenarios" / "cube8.toml"
LAND_AT = 15.0


def land_run(method: str, out: Path) -> dict:
    """The run's JSON. Its exit status is the safety verdict's (gcs.exit_codes): 0 for a
    safe run, 3 for a filter's run that is not (the paper's rcbf lets cube8's crossing
    followers below h = 0 early on, docs/safety.md)."""
    proc = subprocess.run(
        [sys.executable, "-m", "gcs.cli", "mission", "run", str(CUBE8), "--inproc",
         "--method", method, "--duration", "30", "--land-at", str(LAND_AT), "--json",
         "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )
    doc = json.loads(proc.stdout)
    safe = doc["metrics"]["safety_verdict"] == "safe"
    assert proc.returncode == (EXIT_OK if safe else EXIT_SAFETY), proc.stderr[-2000:]
    return doc


@pytest.mark.parametrize(("method", "pad_tol"), [("rcbf", 0.1), ("dcbf", 0.5)])
def test_land_all_cube8_safe_and_on_pads(tmp_path: Path, method: str, pad_tol: float) -> None:
    doc = land_run(method, tmp_path)
    m = doc["metrics"]
    assert m["collisions"] == 0
    assert m["min_distance_m"] >= 0.5
    ser = np.load(tmp_path / "series.npz")
    p_end = ser["p"][-1]
    assert np.all(p_end[:, 2] <= 0.1)
    sc = load_scenario(CUBE8)
    pads = landing_plan(sc, LAND_AT).pads
    # dcbf pushes the outer pads' vehicles up to ~0.4 m outward during the descent
    assert np.all(np.linalg.norm(p_end[:, :2] - pads, axis=1) <= pad_tol)
    # the landing phase itself keeps the vehicles far apart (stacked layers on distinct pads)
    t = ser["t"]
    assert ser["min_dist"][t >= LAND_AT].min() >= 1.0


@pytest.mark.slow
def test_distributed_land_all_matches_inproc(tmp_path: Path) -> None:
    """The Zenoh land command (gcs.mission.distributed, offboard.daemon.core) reproduces the
    in-process
    land-all to float32 wire rounding (< 1e-6 m; test_mission_distributed)."""
    sc = load_scenario(CUBE8)
    ref = run_inproc(sc, "rcbf", duration=30.0, land_at=LAND_AT)
    rec, facts = run_distributed(
        sc, tmp_path, "rcbf", None, 30.0, port_offset=free_port_offset(), show_progress=False,
        land_at=LAND_AT, processes=2,  # packed: the same run (test_mission_packed), cheaper
    )
    m, ser = recorded_metrics(rec, sc, facts["wall_s"], 30.0)
    if not lockstep_misses(facts):  # equal unless lockstep gave up a wait and said so
        assert np.max(np.abs(ser.p - ref.series.p)) < 1e-6
    assert m["collisions"] == ref.metrics["collisions"] == 0
    assert np.all(ser.p[-1, :, 2] <= 0.1)
