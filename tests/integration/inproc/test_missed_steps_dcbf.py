"""A starved real-time swarm: every daemon misses control steps at random and its vehicle
flies the last command meanwhile. The dcbf filter's relative-acceleration difference and
its inputs then span the missed periods (FollowerAgent._coast_missed,
DcbfFilter.set_span). Divided by one period, a step after m missed ones saw an m-fold
relative acceleration: spurious barrier rows, saturated escapes, and followers thrown
to 12-17 m above a 6.4 m formation (a CI run's ground8 dashboard test: 48 m).
Checked on the real swarm dynamics, seeded."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CUBE8, ROOT

from gcs.mission.agents.wire_form import f32, round_estimate, wire_to_command
from offboard.agent.factory import FollowerAgent, make_agent
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario
from vehicle_sim.physics.dynamics import SwarmDynamics

GROUND8 = str(ROOT / "scenarios" / "ground8.toml")


def _fly(path: str, p_miss: float, max_burst: int, seed: int, t_end: float = 20.0):
    """(highest altitude of any vehicle (m), least pair distance (m), largest span seen)
    with each agent skipping a step with probability ``p_miss`` after t = 1 s, then
    0..max_burst−1 more (its vehicle keeps the last command meanwhile)."""
    sc = load_scenario(path)
    form = formation_from_scenario(sc)
    dyn = SwarmDynamics(sc, seed=1)
    agents = [make_agent(sc, a.id, seed=1, form=form, method="dcbf") for a in sc.agents]
    published = {ag.id: round_estimate(ag.initial_estimate()) for ag in agents}
    dt, nsub, f_max = sc.control_dt, sc.substeps_per_control, sc.vehicle.thrust_max_n
    rng = np.random.default_rng(seed)
    skip = [0] * len(agents)
    z_max, d_min, span_max = 0.0, np.inf, 1
    for k in range(int(round(t_end / dt))):
        t = k * dt
        tp, tv = f32(dyn.p), f32(dyn.v)
        new_pub = dict(published)
        for i, ag in enumerate(agents):
            if skip[i] > 0:
                skip[i] -= 1
                continue
            if t > 1.0 and rng.random() < p_miss:
                skip[i] = int(rng.integers(0, max_burst))
                continue
            nb = {j: v for j, v in published.items() if j != ag.id}
            out = ag.step(k, t, tp, tv, nb, True)
            if isinstance(ag, FollowerAgent):
                span_max = max(span_max, ag._span)
            dyn.set_command(i, *wire_to_command(out.q_ned, out.thrust_norm, f_max))
            new_pub[ag.id] = round_estimate(out.estimate)
        published = new_pub
        for _ in range(nsub):
            dyn.step()
        z_max = max(z_max, float(dyn.p[:, 2].max()))
        d = np.linalg.norm(dyn.p[:, None] - dyn.p[None], axis=2) + 1e9 * np.eye(len(agents))
        d_min = min(d_min, float(d.min()))
    return z_max, d_min, span_max


@pytest.mark.parametrize(("path", "seed"), [(CUBE8, 1), (CUBE8, 3), (GROUND8, 2)])
def test_starved_swarm_keeps_its_altitude(path: str, seed: int) -> None:
    z_ref, d_ref, span_ref = _fly(path, 0.0, 1, seed)
    z, d, span = _fly(path, 0.5, 5, seed)
    assert span_ref == 1 and span >= 5  # the starved run did miss runs of steps
    # measured: cube8 8.12 m and ground8 7.82 m every step; starved 8.26-8.59 m with the
    # span (14.6-17.7 m with a one-period difference)
    assert z < z_ref + 1.0, (z, z_ref)
    assert d > 0.8 * d_ref, (d, d_ref)
