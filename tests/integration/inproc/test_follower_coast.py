"""A follower whose daemon misses control steps (lost ODOMETRY in real time) keeps its
DESO on the vehicle: the missed periods are coasted with the last setpoint
(FollowerAgent._coast_missed). Checked on the real swarm dynamics."""

from __future__ import annotations

import numpy as np
from conftest import CUBE8

from gcs.mission.agents.wire_form import f32, round_estimate, wire_to_command
from offboard.agent.factory import FollowerAgent, make_agent
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario
from vehicle_sim.physics.dynamics import SwarmDynamics

VICTIM = 3  # scenario index of a follower


def _run(coast: bool, skip_every: int = 3, t_end: float = 6.0) -> float:
    """Max |DESO z1 − p| of the victim after its steps in the second half, where it
    misses every ``skip_every``-th step (its vehicle keeps the last command meanwhile)."""
    sc = load_scenario(CUBE8)
    form = formation_from_scenario(sc)
    dyn = SwarmDynamics(sc, seed=1)
    agents = [make_agent(sc, a.id, seed=1, form=form) for a in sc.agents]
    victim = agents[VICTIM]
    assert isinstance(victim, FollowerAgent)
    published = {ag.id: round_estimate(ag.initial_estimate()) for ag in agents}
    dt, nsub = sc.control_dt, sc.substeps_per_control
    worst = 0.0
    for k in range(int(round(t_end / dt))):
        t = k * dt
        tp, tv = f32(dyn.p), f32(dyn.v)
        new_pub = dict(published)
        for i, ag in enumerate(agents):
            if i == VICTIM and t > t_end / 2 and k % skip_every == 0:
                continue  # this step's ODOMETRY was lost: no step, the command stays
            if i == VICTIM and not coast:
                ag.last_k = None  # type: ignore[attr-defined]  # switch the catch-up off
            nb = {j: v for j, v in published.items() if j != ag.id}
            out = ag.step(k, t, tp, tv, nb, True)
            f_max = sc.vehicle.thrust_max_n
            dyn.set_command(i, *wire_to_command(out.q_ned, out.thrust_norm, f_max))
            new_pub[ag.id] = round_estimate(out.estimate)
        published = new_pub
        for _ in range(nsub):
            dyn.step()
        if t > t_end / 2 + 0.5 and k % skip_every != 0:  # z1 is valid for t_{k+1}: now
            worst = max(worst, float(np.linalg.norm(victim.deso.z1 - dyn.p[VICTIM])))
    return worst


def test_missed_steps_are_coasted_not_lost() -> None:
    for skip_every in (2, 3):
        with_coast = _run(coast=True, skip_every=skip_every)
        without = _run(coast=False, skip_every=skip_every)
        # without the catch-up the DESO falls a period behind at every missed stamp
        # (measured: 0.012 m and 0.017 m; with it 0.008 m)
        assert with_coast < 0.01, with_coast
        assert with_coast < 0.8 * without, (with_coast, without)
