"""Reference governor (offboard.agent.governor, docs/saturation.md §3): κ from the load-time
feasibility numbers, the slowed exosystem fits the input set."""

import math

import numpy as np

from offboard.agent.governor import _at_frequency, _origins, first_guess, governor_for
from offboard.estimation.reference import LeaderTrajectory, exo_propagator
from swarm_common.scenario.feasibility import FEEDBACK_RESERVE, acceleration_problem
from swarm_common.scenario.input_set import InputSet
from swarm_common.scenario.model import load_scenario, with_overrides

CUBE8 = "scenarios/cube8.toml"


def _fast():
    return with_overrides(
        load_scenario(CUBE8, allow_infeasible=True), leader_trajectory={"frequency_hz": 0.4}
    )


def test_feasible_scenario_is_not_slowed():
    sc = load_scenario(CUBE8)
    gov = governor_for(sc)
    assert gov.kappa == 1.0 and not gov.slowed
    assert gov.frequency_hz == sc.leader_trajectory.frequency_hz


def test_infeasible_trajectory_is_slowed_to_the_largest_fitting_frequency():
    sc = _fast()
    gov = governor_for(sc)
    assert 0.5 < gov.kappa < 1.0 and gov.slowed
    assert math.isclose(gov.frequency_hz, gov.kappa * 0.4)
    # κ never exceeds the pure-acceleration guess sqrt(a_avail / a_need)
    assert gov.kappa <= first_guess(sc) + 1e-12
    origins, idx = _origins(sc)
    assert acceleration_problem(_at_frequency(sc, gov.frequency_hz), origins, idx) is None
    assert acceleration_problem(_at_frequency(sc, 1.01 * gov.frequency_hz), origins, idx)


def test_slowed_exosystem_acceleration_fits_the_input_set():
    sc = _fast()
    gov = governor_for(sc)
    amp = np.array(sc.leader_trajectory.amplitude_m)
    traj = LeaderTrajectory(np.zeros(3), amp, gov.frequency_hz)
    dt = 0.02
    phi = exo_propagator(gov.omega, dt)
    xi = traj.state(0.0)
    tau = np.array([sc.vehicle.tau_rollpitch_s] * 2 + [sc.vehicle.tau_thrust_s])
    lim = InputSet.of(sc.vehicle, sc.controller)
    peak = 0.0
    for k in range(1, int(1.0 / gov.frequency_hz / dt) + 1):
        xi = phi @ xi  # the followers' exosystem generates the leaders' governed motion
        assert np.allclose(xi, traj.state(k * dt), atol=1e-6)
        u_ff = xi[6:9] + tau * xi[9:12]  # a + τ ȧ
        assert np.linalg.norm(u_ff[:2]) < lim.horizontal(u_ff[2], FEEDBACK_RESERVE)
        peak = max(peak, float(np.linalg.norm(u_ff[:2])))
    # while the nominal trajectory needs more than the whole input set
    w = 2.0 * math.pi * 0.4
    assert np.linalg.norm(amp[:2]) * w * w > lim.horizontal(0.0, 0.0)
    assert peak > 0.5 * lim.horizontal(0.0, FEEDBACK_RESERVE)  # slowed, not stopped


def test_governor_is_computed_once_per_scenario_object() -> None:
    from dataclasses import replace

    import offboard.agent.governor as gov_mod

    sc = load_scenario(CUBE8)
    calls = []
    real = gov_mod._governor

    def counting(s):  # type: ignore[no-untyped-def]
        calls.append(s)
        return real(s)

    gov_mod._governor = counting
    try:
        a = governor_for(sc)
        assert governor_for(sc) is a and len(calls) == 1
        other = replace(sc, leader_trajectory=replace(sc.leader_trajectory, frequency_hz=0.05))
        b = governor_for(other)  # another scenario object: computed for it
        assert len(calls) == 2 and b.nominal_hz == 0.05
    finally:
        gov_mod._governor = real
