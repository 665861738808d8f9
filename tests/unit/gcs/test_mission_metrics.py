"""Mission metrics (gcs.report.mission_metrics): desired positions of a turning formation
and the mission's completion, time and transit error."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gcs.report.mission_metrics import leader_yaw, mission_metrics, yawed_desired
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.mission_check import plan_for
from swarm_common.scenario.model import parse_scenario

ROOT = Path(__file__).resolve().parents[3]


def course():
    data = tomllib.loads((ROOT / "scenarios" / "cube8.toml").read_text())
    del data["leader_trajectory"]
    data["mission"] = {"speed_mps": 1.5, "max_speed_mps": 3.0, "max_accel_mps2": 1.0,
                       "max_jerk_mps3": 2.0, "waypoint": [
                           {"centroid": [2.0, 2.0, 4.0], "hold_s": 1.0},
                           {"centroid": [10.0, 2.0, 4.0], "yaw_deg": 90.0, "scale": 1.3},
                           {"centroid": [10.0, 10.0, 5.0], "yaw_deg": 135.0}]}
    return parse_scenario(data)


def planned(sc, t):
    plan = plan_for(sc)
    xi = np.array([plan.all_xi(x) for x in t])
    return xi[..., 0:3], xi[..., 3:6]


def test_the_bearing_map_of_a_turned_formation_gives_the_planned_shape():
    """Two independent constructions agree: the plan's p = c + s R(ψ) q, and the bearing
    map from the leaders' positions alone with ψ read from them (1e-9 m, 1e-9 m/s)."""
    sc = course()
    form = formation_from_scenario(sc)
    t = np.linspace(0.0, plan_for(sc).end_s, 400)
    p, v = planned(sc, t)
    psi, psi_dot = leader_yaw(sc, p, v)
    assert np.ptp(psi) > 2.0  # it turns (135°)
    p_des, v_des = yawed_desired(form, form.leader_idx, p, v, psi, psi_dot)
    np.testing.assert_allclose(p_des, p, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v_des, v, rtol=0, atol=1e-9)


def test_a_flown_plan_completes_at_its_last_arrival_with_zero_transit_error():
    sc = course()
    plan = plan_for(sc)
    t = np.arange(0.0, plan.end_s + 2.0, 0.02)
    p, _ = planned(sc, t)
    f = [1, 2, 3]
    m = mission_metrics(sc, t, p, p, f)
    assert m["mission_completed"] is True
    # the centroid enters the 0.5 m ball before the plan's arrival, never after it
    assert plan.arrival_s[-2] < m["mission_time_s"] <= plan.arrival_s[-1]
    assert m["transit_error_rms_m"] == 0.0 and m["transit_error_max_m"] == 0.0


def test_transit_error_is_over_the_window_only_and_a_short_run_is_not_complete():
    sc = course()
    plan = plan_for(sc)
    t = np.arange(0.0, plan.end_s + 2.0, 0.02)
    p, _ = planned(sc, t)
    off = p.copy()
    t0, t1 = plan.transit_window
    inside = (t >= t0) & (t <= t1)
    off[inside, 2, 0] += 0.3  # follower index 2 off by 0.3 m during the transit only
    off[~inside, 3, 0] += 5.0  # and follower 3 far off outside it: not counted
    m = mission_metrics(sc, t, off, p, [2, 3])
    assert abs(m["transit_error_max_m"] - 0.3) < 1e-12
    assert abs(m["transit_error_rms_m"] - 0.3 / np.sqrt(2)) < 1e-12
    short = t < plan.arrival_s[-1] - 5.0
    cut = mission_metrics(sc, t[short], p[short], p[short], [2, 3])
    assert cut["mission_completed"] is False and cut["mission_time_s"] is None


@pytest.mark.full
def test_the_mission_table_and_path_plot(tmp_path):
    from gcs.report.comparison import mission_table
    from gcs.report.plots import plot_mission_path

    sc = course()
    plan = plan_for(sc)
    t = np.arange(0.0, plan.end_s, 0.1)
    p, _ = planned(sc, t)
    plot_mission_path({"dcbf": {"t": t, "p": p}}, plan, tmp_path / "path.png")
    assert (tmp_path / "path.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    m = mission_metrics(sc, t, p, p, [1, 2, 3])
    table = mission_table({"dcbf": {**m, "ref_est_max_m": None}}, plan)
    row = table.splitlines()[-1]
    assert row.startswith("| Sampled-data CBF (ours) | yes |") and row.endswith("| – |")
    assert f"{m['mission_time_s']:.3f}" in row


def test_the_sweep_summary_counts_missions_and_skips_sweeps_without():
    from gcs.report.sweep import mission_table as sweep_missions

    def row(seed, done, rms, scen="course", ref=0.01):
        return {"scenario": scen, "method": "dcbf", "seed": seed, "status": "ok",
                "mission_completed": done, "transit_error_rms_m": rms,
                "transit_error_max_m": 2 * rms, "ref_est_max_m": ref}

    rows = [row(1, True, 0.01), row(2, True, 0.03), row(3, False, 0.02, ref=0.2),
            {"scenario": "course", "method": "dcbf", "seed": 4, "status": "crashed"}]
    table = sweep_missions(rows, ["dcbf"])
    line = table.splitlines()[-1]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[:4] == ["course", "dcbf", "3", "2/3"]
    assert cells[5] == "0.020 / 0.030" and cells[6] == "0.060" and cells[7] == "0.200"
    plain = [{**r, "mission_completed": None} for r in rows[:3]]
    assert sweep_missions(plain, ["dcbf"]) is None


def test_an_incomplete_mission_is_a_warning_in_the_log(caplog):
    import logging

    from gcs.mission.run_output import empty_series, run_mission_metrics
    from offboard.estimation.bearing import formation_from_scenario

    sc = course()
    plan = plan_for(sc)
    t = np.arange(0.0, plan.arrival_s[-1] - 5.0, 0.1)  # the run ends before the last arrival
    ser = empty_series(t, sc.n)
    ser.p[:], _ = planned(sc, t)
    ser.p_des[:] = ser.xi_p[:] = ser.p
    with caplog.at_level(logging.WARNING):
        m = run_mission_metrics(sc, ser, formation_from_scenario(sc))
    assert m["mission_completed"] is False
    assert "did not reach every mission waypoint" in caplog.text
    caplog.clear()
    t = np.arange(0.0, plan.end_s + 1.0, 0.1)
    ser = empty_series(t, sc.n)
    ser.p[:], _ = planned(sc, t)
    ser.p_des[:] = ser.xi_p[:] = ser.p
    with caplog.at_level(logging.WARNING):
        assert run_mission_metrics(sc, ser, formation_from_scenario(sc))["mission_completed"]
    assert "did not reach" not in caplog.text
