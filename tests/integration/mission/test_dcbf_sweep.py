"""dcbf in process on swap_centre and cube8 over 3 seeds (15 s each): the TRUE barrier
h = ‖Δp‖² + 2τΔvᵀΔp − D² of every pair with a follower stays ≥ 0 at every step, the
minimum distance ≥ D_safe, no collision and no clipped input (docs/safety.md)."""

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT  # noqa: E402

from gcs.report.safety_metrics import clipped_steps, true_barrier
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario

CASES = [(name, seed) for name in ("swap_centre", "cube8") for seed in (1, 2, 3)]

@pytest.mark.parametrize(("name", "seed"), CASES)
def test_dcbf_true_barrier_nonnegative(name, seed, tmp_path):
    path = ROOT / "scenarios" / f"{name}.toml"
    sc = load_scenario(path)
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "gcs.cli", "mission", "run", str(path), "--inproc",
           "--method", "dcbf", "--seed", str(seed), "--duration", "15", "--json",
           "--out", str(out)]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    doc = json.loads(res.stdout)
    ser = np.load(out / "series.npz")
    fol = formation_from_scenario(sc).follower_idx
    ctl = sc.controller
    tb = true_barrier(ser["p"], ser["v"], fol, ctl.tau_safe_s, ctl.d_safe_m)
    assert tb.h_min >= 0.0, f"true h_min {tb.h_min:.3f} m², {tb.neg_pair_steps} pair-steps < 0"
    assert tb.dist_min >= ctl.d_safe_m
    assert doc["metrics"]["min_distance_m"] >= ctl.d_safe_m
    assert doc["metrics"]["collisions"] == 0
    assert clipped_steps(ser["u"], fol, sc.vehicle) == 0


@pytest.mark.parametrize(("name", "seed"), [("swap_centre", 4)])
def test_dcbf_previously_deadlocked_case_forms(name, seed, tmp_path):
    """swap_centre seed 4 never formed in 30 s while C1's ē margin was linearised at ĥ_T
    (a follower stopped ≈ 2.9 m from the corners of the cube face it had to cross,
    docs/safety.md §6); it must form, safely."""
    path = ROOT / "scenarios" / f"{name}.toml"
    cmd = [sys.executable, "-m", "gcs.cli", "mission", "run", str(path), "--inproc",
           "--method", "dcbf", "--seed", str(seed), "--duration", "30", "--json",
           "--out", str(tmp_path / "run")]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    met = json.loads(res.stdout)["metrics"]
    assert met["formation_time_s"] is not None, f"no formation, rms {met['tracking_rms_m']}"
    assert met["h_min"] >= 0.0
    assert met["collisions"] == 0
    assert met["input_clipped_steps"] == 0
