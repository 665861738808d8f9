"""Load-time feasibility (swarm_common.scenario.feasibility): the desired motion against the
formation
maths of offboard (finite differences of p*(t)), the input set against offboard.safety.dcbf.model,
and
the one-line refusals (key and numbers) of infeasible scenarios."""

from __future__ import annotations

import logging
import math
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, load_shipped

from gcs.mission.launch_spec import LaunchSpec
from offboard.agent.takeoff import leader_origin
from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.reference import LeaderTrajectory
from offboard.safety.dcbf.filter import input_set_of
from swarm_common.scenario.feasibility import (
    FEEDBACK_RESERVE,
    desired_origins,
    feasibility_problem,
    leader_origins,
    peak_acceleration,
)
from swarm_common.scenario.input_set import InputSet
from swarm_common.scenario.model import (
    InfeasibleScenarioError,
    Scenario,
    ScenarioError,
    load_scenario,
    parse_scenario,
    with_overrides,
)

SCENARIOS = sorted((ROOT / "scenarios").glob("*.toml"))
CUBE8 = ROOT / "scenarios" / "cube8.toml"


def _variant(base: Path = CUBE8, allow: bool = True, **sections: dict) -> Scenario:
    """``base`` with some keys replaced, loaded with the check waived (tested separately)."""
    sc = load_scenario(base)
    data = sc.to_toml_dict()
    for sec, kv in sections.items():
        data[sec].update(kv)
    return parse_scenario(data, "variant.toml", allow_infeasible=allow, allow_unsafe=True)


def _write(tmp_path: Path, old: str, new: str) -> Path:
    text = CUBE8.read_text()
    assert old in text
    p = tmp_path / "x.toml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_are_feasible(path):
    sc = load_shipped(path)
    assert feasibility_problem(sc) is None
    assert not sc.allow_infeasible


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_desired_origins_are_offboards_formation(path):
    sc = load_shipped(path)
    form = formation_from_scenario(sc)
    lead = [sc.index_of(i) for i in sc.leader_ids]
    lo = np.array([leader_origin(sc, k) for k in lead])
    assert np.allclose(leader_origins(sc), lo, atol=1e-12)
    origins = desired_origins(sc)
    assert origins is not None
    assert np.allclose(origins, form.desired_positions(lo), atol=1e-9)


def test_desired_origins_with_leaders_off_the_vertex_bearing():
    """Leaders whose offset is not along their vertices' (no exact formation): the affine map
    is still offboard's −L_ff⁻¹ L_fl."""
    sc = load_scenario(CUBE8)
    data = sc.to_toml_dict()
    data["agent"][1]["position"] = [4.6, 4.0, 6.8]
    sc2 = parse_scenario(data, "skew.toml", allow_infeasible=True)
    form = formation_from_scenario(sc2)
    lo = leader_origins(sc2)
    origins = desired_origins(sc2)
    assert origins is not None
    assert np.allclose(origins, form.desired_positions(lo), atol=1e-9)


def test_peak_acceleration_and_jerk_match_finite_differences_of_the_formation():
    """p*(t) = −L_ff⁻¹ L_fl p_L(t) sampled on a fine grid and differenced: every agent's
    per-axis peak acceleration and jerk are the leaders' |A|ω², |A|ω³."""
    sc = _variant(leader_trajectory={"frequency_hz": 0.4, "amplitude_m": [0.8, -0.4, 0.3]})
    form = formation_from_scenario(sc)
    lt = sc.leader_trajectory
    trs = [LeaderTrajectory(leader_origin(sc, k), np.array(lt.amplitude_m), lt.frequency_hz)
           for k in form.leader_idx]
    h = 1e-3
    t = np.arange(0.0, 1.0 / lt.frequency_hz + 4 * h, h)
    p = np.array([form.desired_positions(np.array([tr.state(tk)[:3] for tr in trs]))
                  for tk in t])
    acc = np.diff(p, 2, axis=0) / h**2  # (T, N, 3)
    jerk = np.diff(p, 3, axis=0) / h**3
    a_pk, j_pk = peak_acceleration(sc)
    w = 2 * math.pi * lt.frequency_hz
    assert np.allclose(a_pk, np.abs(lt.amplitude_m) * w * w)
    for k in range(sc.n):
        assert np.allclose(np.abs(acc[:, k]).max(axis=0), a_pk, rtol=1e-3, atol=1e-4)
        assert np.allclose(np.abs(jerk[:, k]).max(axis=0), j_pk, rtol=5e-3, atol=1e-3)


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_the_load_time_input_set_is_the_dcbf_filters_and_is_realisable(path):
    """One input set: the feasibility check's is the dcbf filter's; and every point of it is
    realisable, checked numerically against the vehicle's tilt and thrust limits."""
    sc = load_shipped(path)
    veh, ctl = sc.vehicle, sc.controller
    lim = InputSet.of(veh, ctl)
    dcbf = input_set_of(ctl, veh)
    assert isinstance(dcbf, InputSet)
    assert (lim.uz_min, lim.uz_max, lim.tan_tilt, lim.sides, lim.uh_max, lim.g) == (
        dcbf.uz_min, dcbf.uz_max, dcbf.tan_tilt, dcbf.sides, dcbf.uh_max, dcbf.g)
    rng = np.random.default_rng(4)
    a, lo, hi = lim.rows()
    for _ in range(500):
        u = rng.uniform(-2 * lim.uh_max, 2 * lim.uh_max, 3)
        if not ((a @ u <= hi).all() and (a @ u >= lo).all()):
            continue
        thrust_dir = u + np.array([0.0, 0.0, lim.g])  # specific force the rotors make
        tilt = math.degrees(math.atan2(np.linalg.norm(thrust_dir[:2]), thrust_dir[2]))
        assert tilt <= veh.tilt_max_deg + 1e-9
        assert veh.mass_kg * np.linalg.norm(thrust_dir) <= veh.thrust_max_n + 1e-9
    # the set scaled by 1 − r about hover: a point on its horizontal edge is in the set
    uz = -1.0
    r = float(lim.horizontal(np.array(uz), reserve=0.0))
    assert dcbf.contains(np.array([r, 0.0, uz]), tol=1e-9)
    assert not dcbf.contains(np.array([r + 0.05, 0.0, uz]))


def _numbers(msg: str, word: str) -> tuple[float, float]:
    need = re.search(rf"needs ([0-9.]+) m/s² {word}", msg)
    allow = re.search(r"allows ([0-9.]+) m/s²", msg)
    assert need and allow, msg
    return float(need.group(1)), float(allow.group(1))


def test_horizontal_need_is_the_lag_inverted_peak():
    """No disturbance, no unmodeled dynamics, no vertical motion: the need is
    max_t ‖a_h + τ ȧ_h‖ = ‖A_h‖ω²√(1 + (ωτ)²), the allowance 0.8·g·tanθ·cos(π/K)."""
    sc = _variant(
        leader_trajectory={"frequency_hz": 0.4, "amplitude_m": [0.8, 0.4, 0.0]},
        disturbance={"amplitude_n": 0.0},
        unmodeled={"zeta_nominal": [0.0] * 6, "zeta_spread": 0.0},
    )
    msg = feasibility_problem(sc)
    assert msg is not None and msg.startswith("leader_trajectory.frequency_hz = 0.4")
    need, allow = _numbers(msg, "horizontally")
    w, tau = 2 * math.pi * 0.4, sc.vehicle.tau_rollpitch_s
    assert need == pytest.approx(math.hypot(0.8, 0.4) * w * w * math.hypot(1, w * tau), abs=0.01)
    k = 1 - FEEDBACK_RESERVE
    slope = math.tan(math.radians(30)) * math.cos(math.pi / 8)
    assert allow == pytest.approx(k * 9.81 * slope, abs=0.01)


def test_infeasible_trajectory_refused_in_one_line_naming_the_key(tmp_path):
    p = _write(tmp_path, "frequency_hz = 0.2", "frequency_hz = 0.4")
    with pytest.raises(InfeasibleScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith(f"{p}: leader_trajectory.frequency_hz = 0.4")
    assert "--allow-infeasible" in msg and "vehicle.tilt_max_deg = 30" in msg
    need, allow = _numbers(msg, "horizontally")
    assert need > allow > 0
    assert isinstance(ei.value, ScenarioError)


def test_allow_infeasible_logs_a_warning_and_is_inherited(tmp_path, caplog):
    p = _write(tmp_path, "frequency_hz = 0.2", "frequency_hz = 0.4")
    with caplog.at_level(logging.WARNING, logger="swarm_common.scenario.model"):
        sc = load_scenario(p, allow_infeasible=True)
    assert sc.allow_infeasible
    assert any("leader_trajectory.frequency_hz = 0.4" in r.getMessage() for r in caplog.records)
    assert with_overrides(sc, sensing={"dropout_prob": 0.1}).allow_infeasible
    with pytest.raises(InfeasibleScenarioError):
        parse_scenario(sc.to_toml_dict(), str(p))


def test_disturbance_beyond_the_input_set_names_the_disturbance():
    sc = _variant(disturbance={"amplitude_n": 10.0})  # 5.6 m/s² on a 1.8 kg vehicle
    msg = feasibility_problem(sc)
    assert msg is not None and msg.startswith("disturbance.amplitude_n = 10:"), msg


def test_follower_vertex_below_the_ground_is_refused():
    """Leaders at z = 6 dipping 2 m: the bottom layer (z = 2) reaches z = 0 < d_safe."""
    sc = _variant(leader_trajectory={"frequency_hz": 0.05, "amplitude_m": [0.0, 0.0, -1.0]})
    msg = feasibility_problem(sc)
    assert msg is not None and msg.startswith("agent[3].vertex = [0, 0, 0]:"), msg
    assert "z = 0.00 m" in msg and "controller.d_safe_m = 0.5" in msg


def test_leader_below_the_ground_is_refused_first():
    sc = _variant(leader_trajectory={"frequency_hz": 0.05, "amplitude_m": [0.0, 0.0, -3.0]})
    msg = feasibility_problem(sc)
    assert msg is not None and msg.startswith("agent[0].position = [4, 0, 6]: leader id 1"), msg


def test_ground_start_staging_too_low_is_refused():
    ground8 = ROOT / "scenarios" / "ground8.toml"
    sc = _variant(ground8, lifecycle={"takeoff_altitude_m": 0.3})
    msg = feasibility_problem(sc)
    assert msg is not None and "z = 0.30 m" in msg and "below the ground clearance" in msg, msg


def test_launched_processes_inherit_allow_infeasible(tmp_path):
    p = _write(tmp_path, "frequency_hz = 0.2", "frequency_hz = 0.4")
    for allow in (False, True):
        sc = load_scenario(p if allow else CUBE8, allow_infeasible=allow)
        spec = LaunchSpec(sc, seed=3)
        for argv in (spec.sim_argv(), spec.daemon_argv(1)):
            assert ("--allow-infeasible" in argv) is allow, argv
            assert argv[argv.index("--seed") + 1] == "3"
