"""The in-process runner's all-agents-at-once conversions against the per-agent functions
they stand for (the simulator's decoding of each setpoint, the float32 trip of each
estimate, each agent's command and status record): the same bits, non-finite input
included."""

from __future__ import annotations

import math

import numpy as np

from gcs.inproc import round_estimate, round_estimates, wire_to_command, wire_to_commands
from gcs.run_output import empty_series, set_agent_row, set_agent_rows
from offboard.agent_types import AgentOutput, AgentStatus, NeighbourEstimate
from offboard.attitude import quat_ned_fast
from swarm_common.enums import Method, QPStatus
from swarm_common.scenario import load_scenario
from vehicle_sim.dynamics import SwarmDynamics

SC = load_scenario("scenarios/cube8.toml")


def _quats(rng: np.random.Generator, n: int) -> np.ndarray:
    q = np.array([quat_ned_fast(*rng.uniform(-3.2, 3.2, 3)) for _ in range(n)])
    q[0] *= 1.0 + 1e-3  # not quite unit: normalised by the decoder
    return q.astype(np.float32)


def test_setpoints_decoded_at_once_are_the_simulators_decoding() -> None:
    rng = np.random.default_rng(1)
    f_max = SC.vehicle.thrust_max_n
    for _ in range(200):
        n = int(rng.integers(1, 12))
        q = _quats(rng, n)
        tn = rng.uniform(-0.1, 1.1, n).astype(np.float32)
        got = wire_to_commands(q, tn, f_max)
        for i in range(n):
            want = wire_to_command(q[i], tn[i], f_max)
            assert tuple(float(a[i]) for a in got) == want


def test_commands_set_at_once_equal_one_by_one() -> None:
    rng = np.random.default_rng(2)
    one, many = SwarmDynamics(SC, seed=3), SwarmDynamics(SC, seed=3)
    for trial in range(300):
        cmd = rng.uniform(-1.5, 1.5, (SC.n, 4))
        cmd[:, 3] = rng.uniform(-10.0, 1.3 * one.f_max, SC.n)
        if trial % 4 == 0:
            cmd[int(rng.integers(0, SC.n)), int(rng.integers(0, 4))] = [
                math.nan, math.inf, -math.inf][trial % 3]
        for i in range(SC.n):
            one.set_command(i, *(float(c) for c in cmd[i]))
        many.set_commands(cmd[:, 0], cmd[:, 1], cmd[:, 2], cmd[:, 3])
        assert np.array_equal(one.cmd_att, many.cmd_att), trial
        assert np.array_equal(one.cmd_thrust, many.cmd_thrust), trial


def _estimate(rng: np.random.Generator, aid: int) -> NeighbourEstimate:
    return NeighbourEstimate(aid, float(rng.uniform(0, 60)), rng.normal(size=3) * 10,
                             rng.normal(size=3), rng.normal(size=3), rng.normal(size=12),
                             bool(rng.random() < 0.3))


def test_estimates_rounded_at_once_equal_one_by_one() -> None:
    rng = np.random.default_rng(3)
    ests = [_estimate(rng, aid) for aid in range(1, 10)]
    for got, e in zip(round_estimates(ests), ests, strict=True):
        want = round_estimate(e)
        assert (got.id, got.t, got.is_leader, got.cooperative) == (
            want.id, want.t, want.is_leader, want.cooperative)
        for a, b in ((got.z1, want.z1), (got.z2, want.z2), (got.z3, want.z3),
                     (got.xi, want.xi)):
            assert np.array_equal(a, b) and a.flags.c_contiguous


def test_status_rows_written_at_once_equal_one_by_one() -> None:
    rng = np.random.default_rng(4)
    n = 5
    one, many = empty_series(np.arange(3) * 0.02, n), empty_series(np.arange(3) * 0.02, n)
    statuses = list(QPStatus)
    outs = []
    for i in range(n):
        st = AgentStatus(Method.DCBF, qp_status=statuses[i % len(statuses)],
                         solve_us=float(rng.uniform(0, 50)),
                         h_min=[math.inf, float(rng.normal())][i % 2],
                         input_clipped=bool(i % 2))
        outs.append(AgentOutput(0.0, 0.0, 0.0, 0.0, np.zeros(4, np.float32), np.float32(0.5),
                                rng.normal(size=3), _estimate(rng, i + 1), st,
                                lumped=rng.normal(size=3)))
    for i, o in enumerate(outs):
        st = o.status
        set_agent_row(one, 1, i, o.u, o.lumped, st.h_min, st.solve_us, st.qp_status,
                      st.input_clipped)
    set_agent_rows(many, 1, outs)
    for name in ("u", "lumped_est", "h_min", "solve_us", "fallback", "input_clipped"):
        assert np.array_equal(getattr(one, name), getattr(many, name)), name
