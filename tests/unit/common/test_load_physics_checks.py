"""Physics checks at load (issue 42): a control rate whose sampled loop diverges, a
formation deadline after the end of the run, and DESO gains UNSTABLE on their graph get a
one-line error naming the key, or a warning with --allow-infeasible."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from conftest import CUBE8

from gcs.mission.launch_spec import LaunchError
from gcs.mission.preflight import check_physics
from swarm_common.scenario.feasibility import min_control_hz, sampled_loop_radius
from swarm_common.scenario.model import (
    InfeasibleScenarioError,
    UnsafeScenarioError,
    load_scenario,
    with_overrides,
)
from swarm_common.scenario.safety_check import lag_problem

C1, C0, TAU = 3.0, 7.0, 0.15  # cube8's followers' loop and roll/pitch lag


def _period_map_by_integration(c1: float, c0: float, tau: float, dt: float) -> np.ndarray:
    """The one-period map of x = (e1, ė1, a) found by RK4 integration (1e-4 s steps) of
    ë1 = a, ȧ = (u − a)/τ with u = −c1 ė1(0) − c0 e1(0) held: an independent route to
    the matrix exponential of :func:`sampled_loop_radius`."""
    n = int(round(dt / 1e-4))
    h = dt / n
    cols = []
    for k in range(3):
        x = np.eye(3)[k].copy()
        u = -c1 * x[1] - c0 * x[0]

        def f(y: np.ndarray, u: float = u) -> np.ndarray:
            return np.array([y[1], y[2], (u - y[2]) / tau])

        for _ in range(n):
            k1 = f(x)
            k2 = f(x + 0.5 * h * k1)
            k3 = f(x + 0.5 * h * k2)
            k4 = f(x + h * k3)
            x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        cols.append(x)
    return np.array(cols).T


@pytest.mark.parametrize("hz", [1, 2, 4, 10, 50])
def test_sampled_loop_radius_matches_an_integrated_period_map(hz: int) -> None:
    m = _period_map_by_integration(C1, C0, TAU, 1.0 / hz)
    rho = float(np.max(np.abs(np.linalg.eigvals(m))))
    assert sampled_loop_radius(C1, C0, TAU, 1.0 / hz) == pytest.approx(rho, rel=1e-8)


def test_min_control_hz_is_where_the_radius_crosses_one() -> None:
    need = min_control_hz(C1, C0, TAU, 1.0)
    assert 3.0 < need < 4.0  # cube8: diverges at 1, 2, 3 Hz, converges at 4 Hz
    assert sampled_loop_radius(C1, C0, TAU, 1.0 / (need * (1 + 1e-6))) < 1.0
    assert sampled_loop_radius(C1, C0, TAU, 1.0 / (need * (1 - 1e-3))) >= 1.0


def test_control_hz_1_is_refused_at_load_naming_the_key() -> None:
    sc = load_scenario(CUBE8)
    with pytest.raises(InfeasibleScenarioError) as err:
        with_overrides(sc, scenario={"control_hz": 1})
    line = str(err.value)
    assert "\n" not in line
    assert "scenario.control_hz = 1:" in line and "spectral radius 1.847" in line
    assert "needs control_hz above 3.19" in line and "--allow-infeasible" in line


def test_control_hz_1_with_allow_infeasible_is_a_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING):
        sc = load_scenario(CUBE8, allow_infeasible=True, allow_unsafe=True)
        slow = with_overrides(sc, scenario={"control_hz": 1})
    assert slow.run.control_hz == 1
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert any("scenario.control_hz = 1:" in w and "diverges" in w for w in warned)


def test_the_lag_check_names_the_rate_it_needs() -> None:
    sc = load_scenario(CUBE8, allow_infeasible=True, allow_unsafe=True)
    at4 = lag_problem(with_overrides(sc, scenario={"control_hz": 4}))
    assert at4 is not None and "at scenario.control_hz = 4 (or control_hz >= 7.78)" in at4
    assert lag_problem(with_overrides(sc, scenario={"control_hz": 8})) is None  # 8 > 7.78
    at1 = lag_problem(with_overrides(sc, scenario={"control_hz": 1}))
    assert at1 is not None and at1.startswith("scenario.control_hz = 1: half a period")
    assert "-0." not in at1  # no negative lag bound


def test_a_deadline_at_or_after_the_end_is_refused_naming_both_times() -> None:
    sc = load_scenario(CUBE8)
    with pytest.raises(InfeasibleScenarioError) as err:
        with_overrides(sc, scenario={"duration_s": 20.0})  # deadline 20: empty window
    line = str(err.value)
    assert "scenario.formation_deadline_s = 20:" in line
    assert "scenario.duration_s = 20 s" in line and "tracking metrics would be empty" in line
    assert with_overrides(sc, scenario={"duration_s": 20.5}).run.duration_s == 20.5


def test_unstable_deso_gains_stop_the_runner_or_warn(caplog: pytest.LogCaptureFixture) -> None:
    unstable = {"beta": [9.0, 27.0, 54.0], "leader_anchor": 0.0, "velocity_gain": [0.0, 0.0]}
    sc = with_overrides(load_scenario(CUBE8), observer=unstable)
    with pytest.raises(LaunchError) as err:
        check_physics(sc, 30.0)
    assert "observer.beta = [9, 27, 54]" in str(err.value)
    assert "unstable on this graph" in str(err.value)
    lenient = with_overrides(load_scenario(CUBE8, allow_infeasible=True), observer=unstable)
    with caplog.at_level(logging.WARNING):
        check_physics(lenient, 5.0)  # and a run ending before the deadline (20 s)
    warned = " ".join(r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    assert "observer.beta = [9, 27, 54]" in warned
    assert "formation_deadline_s = 20" in warned and "--duration = 5 s" in warned
    check_physics(load_scenario(CUBE8), 30.0)  # the shipped gains pass: no error


def test_unsafe_is_still_refused_after_feasibility() -> None:
    sc = load_scenario(CUBE8, allow_infeasible=True)
    with pytest.raises(UnsafeScenarioError):
        with_overrides(sc, scenario={"control_hz": 4})


def test_a_lag_no_rate_can_carry_is_left_to_the_lag_check() -> None:
    from swarm_common.scenario.feasibility import rate_problem

    sc = load_scenario(CUBE8, allow_infeasible=True, allow_unsafe=True)
    slow = with_overrides(sc, vehicle={"tau_rollpitch_s": 0.5})  # τ c0 = 3.5 > c1 = 3
    assert sampled_loop_radius(C1, C0, 0.5, 1e-3) >= 1.0  # diverges even at 1 kHz
    assert rate_problem(slow) is None
    assert lag_problem(slow) is not None
