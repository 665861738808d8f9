"""Shortened in-process missions: safety, progress, reproducibility, wire helpers, CLI."""

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT  # noqa: E402

from gcs.mission.agents.wire_form import f32, wire_to_command
from gcs.mission.inproc import run_inproc
from gcs.report.metrics import METRIC_KEYS
from offboard.agent.factory import FollowerAgent, make_agent
from offboard.inner_loop.attitude import setpoint_from_accel
from swarm_common.scenario.model import load_scenario, with_overrides

CUBE8 = ROOT / "scenarios" / "cube8.toml"
SERIES_KEYS = ("t", "p", "v", "p_des", "v_des", "z1", "z2", "xi_p", "lumped_est", "lumped_true",
               "u", "thrust", "tilt_deg", "min_dist", "h_min", "solve_us", "fallback",
               "input_clipped", "alarms",
               # the safety filter's report (gcs.records.series.RunSeries)
               "qp_status", "qp_active", "qp_kinds", "clf_slack", "qp_relax", "u_nom", "u_corr")


@pytest.fixture(scope="module")
def sc():
    return load_scenario(CUBE8)


@pytest.fixture(scope="module")
def rcbf15(sc):
    return run_inproc(sc, "rcbf", duration=15.0)


def test_rcbf_safe_and_forms(rcbf15, sc):
    m = rcbf15.metrics
    assert set(m) == set(METRIC_KEYS)
    assert m["min_distance_m"] >= sc.controller.d_safe_m
    assert m["min_distance_m"] >= 0.75
    assert m["collisions"] == 0
    assert m["formation_time_s"] is not None and m["formation_time_s"] < 15.0
    # tracking is measured over [formation_deadline_s, end] = [20 s, end]: a 15 s run has no
    # window, so the tracking metrics are null (the fixed-window bound is in test_metrics)
    assert m["tracking_max_m"] is None and m["tracking_rms_m"] is None
    assert m["h_min"] is not None and m["barrier_violation_steps"] >= 0
    assert m["max_tilt_deg"] <= 30.0 + 1e-6 and m["max_thrust_n"] <= 52.92
    s = rcbf15.series
    assert np.all(np.isfinite(s.u)) and np.all(np.isfinite(s.z1))


def test_no_avoidance_violates(sc):
    r = run_inproc(sc, "none", duration=4.0)
    assert r.metrics["min_distance_m"] < sc.controller.d_safe_m


def test_reproducible(sc):
    a = run_inproc(sc, "rcbf", duration=1.0)
    b = run_inproc(sc, "rcbf", duration=1.0)
    assert np.array_equal(a.series.p, b.series.p) and np.array_equal(a.series.u, b.series.u)


def test_wire_helpers_match_agent_encoding(sc):
    sp = setpoint_from_accel(np.array([0.7, -0.3, 0.4]), 0.2, sc.vehicle, decode=True)
    cmd = wire_to_command(sp.q_ned, sp.thrust_norm, sc.vehicle.thrust_max_n)
    assert cmd == (sp.roll, sp.pitch, sp.yaw, sp.thrust_n)
    x = np.array([1.0 + 1e-9, np.pi])
    assert np.array_equal(f32(x), np.float32(x).astype(np.float64))


def test_agent_interface_and_method_switch(sc):
    ag = make_agent(sc, 3, method="rcbf")
    assert isinstance(ag, FollowerAgent)
    with pytest.raises(ValueError):
        ag.set_method("magic")
    ag.set_method("apf")
    est = {a.id: make_agent(sc, a.id).initial_estimate() for a in sc.agents if a.id != 3}
    p, v = f32(sc.initial_positions()), f32(sc.initial_velocities())
    out = ag.step(0, 0.0, p, v, est, True)
    assert out.status.method == "apf" and out.estimate.t == pytest.approx(sc.control_dt)
    assert out.q_ned.dtype == np.float32 and np.all(np.isfinite(out.u))
    out2 = ag.step(1, sc.control_dt, p, v, {}, False)  # outage: predicted neighbours
    assert np.all(np.isfinite(out2.u)) and not out2.status.comm_ok


def test_cli_run_json(tmp_path):
    cmd = [sys.executable, "-m", "gcs.cli", "mission", "run", str(CUBE8), "--inproc",
           "--method", "none", "--duration", "0.5", "--json", "--out", str(tmp_path)]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["method"] == "none" and "min_distance_m" in doc["metrics"]
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["metrics"] == doc["metrics"] and saved["gains"] and "collision_pairs" in saved
    with np.load(tmp_path / "series.npz") as z:
        assert set(z.files) == set(SERIES_KEYS) and len(z["t"]) == 25


def test_rcbf_safe_with_sensing_dropouts(sc):
    s2 = with_overrides(sc, sensing={"dropout_prob": 0.1})
    r = run_inproc(s2, "rcbf", duration=5.0)
    assert r.metrics["min_distance_m"] >= s2.controller.d_safe_m
    assert np.all(np.isfinite(r.series.u))
