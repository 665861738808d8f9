"""The in-process runner's all-agents-at-once conversions against the per-agent functions
they stand for (the simulator's decoding of each setpoint, the float32 trip of each
estimate, each agent's command and status record): the same bits, non-finite input
included."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.mission import run_output
from gcs.mission.agents import shards
from gcs.mission.agents.wire_form import (
    round_estimate,
    round_estimates,
    wire_to_command,
    wire_to_commands,
)
from gcs.mission.inproc import run_inproc
from gcs.mission.run_output import AgentRows, empty_series, set_agent_rows
from offboard.estimation.peer_table import EstimateBatch
from offboard.records import ActiveRows, AgentOutput, AgentStatus, NeighbourEstimate
from swarm_common.enums import Method, QPRow, QPStatus
from swarm_common.frames import quat_ned_from_euler_enu
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.setpoints import parse_attitude
from vehicle_sim.physics.dynamics import SwarmDynamics

SC = load_scenario("scenarios/cube8.toml")


def _quats(rng: np.random.Generator, n: int) -> np.ndarray:
    q = np.array([quat_ned_from_euler_enu(*rng.uniform(-3.2, 3.2, 3)) for _ in range(n)])
    q[0] *= 1.0 + 1e-3  # not quite unit: normalised by the decoder
    return q.astype(np.float32)


def test_setpoints_decoded_at_once_are_the_simulators_decoding() -> None:
    """Each row equals what vehicle-sim makes of the SET_ATTITUDE_TARGET carrying it
    (packed and parsed by pymavlink, then vehicle_sim.autopilot.setpoints.parse_attitude), and
    wire_to_command (one agent) equals its row."""
    rng = np.random.default_rng(1)
    f_max = SC.vehicle.thrust_max_n
    mav = mavlink.MAVLink(None, 1, 191)
    for _ in range(100):
        n = int(rng.integers(1, 12))
        q = _quats(rng, n)
        tn = rng.uniform(0.0, 1.0, n).astype(np.float32)
        got = wire_to_commands(q, tn, f_max)
        for i in range(n):
            msg = mavlink.MAVLink_set_attitude_target_message(
                0, 1, 1, 0b00000111, [float(c) for c in q[i]], 0.0, 0.0, 0.0, float(tn[i]))
            parsed = mav.parse_char(msg.pack(mav))
            att, thrust = parse_attitude(parsed, f_max)
            assert (*att, thrust) == tuple(float(a[i]) for a in got)
            assert wire_to_command(q[i], tn[i], f_max) == (*att, thrust)


def _set_command_py(att: np.ndarray, thrust: np.ndarray, i: int, cmd: np.ndarray,
                    lim: float, f_max: float) -> None:
    """SwarmDynamics.set_command as it was written in Python before it was compiled."""
    r, p, y, f = (float(c) for c in cmd)
    if not all(math.isfinite(c) for c in (r, p, y, f)):
        return
    att[i] = min(lim, max(-lim, r)), min(lim, max(-lim, p)), y
    thrust[i] = min(f_max, max(0.0, f))


def test_commands_set_one_by_one_and_at_once() -> None:
    rng = np.random.default_rng(2)
    one, many = SwarmDynamics(SC, seed=3), SwarmDynamics(SC, seed=3)
    att, thrust = one.cmd_att.copy(), one.cmd_thrust.copy()
    for trial in range(300):
        cmd = rng.uniform(-1.5, 1.5, (SC.n, 4))
        cmd[:, 3] = rng.uniform(-10.0, 1.3 * one.f_max, SC.n)
        if trial % 4 == 0:
            cmd[int(rng.integers(0, SC.n)), int(rng.integers(0, 4))] = [
                math.nan, math.inf, -math.inf][trial % 3]
        for i in range(SC.n):
            one.set_command(i, *(float(c) for c in cmd[i]))
            _set_command_py(att, thrust, i, cmd[i], one.tilt_max, one.f_max)
        many.set_commands(cmd[:, 0], cmd[:, 1], cmd[:, 2], cmd[:, 3])
        for dyn in (one, many):
            assert np.array_equal(dyn.cmd_att, att), trial
            assert np.array_equal(dyn.cmd_thrust, thrust), trial


def _estimate(rng: np.random.Generator, aid: int) -> NeighbourEstimate:
    return NeighbourEstimate(aid, float(rng.uniform(0, 60)), rng.normal(size=3) * 10,
                             rng.normal(size=3), rng.normal(size=3), rng.normal(size=12),
                             bool(rng.random() < 0.3), cooperative=bool(rng.random() < 0.7))


def test_estimates_rounded_at_once_equal_one_by_one() -> None:
    """Each estimate's vectors take one float32 trip (what a receiver decodes from the
    wire's float32 block), its time and flags unchanged; round_estimate is one of them."""
    rng = np.random.default_rng(3)
    ests = [_estimate(rng, aid) for aid in range(1, 10)]
    assert len({e.cooperative for e in ests}) == 2  # both flags among them
    for got, e in zip(round_estimates(ests), ests, strict=True):
        one = round_estimate(e)
        assert ((got.id, got.t, got.is_leader, got.cooperative)
                == (e.id, e.t, e.is_leader, e.cooperative))
        for a, b, c in ((got.z1, one.z1, e.z1), (got.z2, one.z2, e.z2),
                        (got.z3, one.z3, e.z3), (got.xi, one.xi, e.xi)):
            want = c.astype(np.float32).astype(np.float64)
            assert np.array_equal(a, want) and np.array_equal(b, want)
            assert a.flags.c_contiguous


def test_status_rows_written_at_once() -> None:
    """Row r of each status field holds every agent's value, in scenario order."""
    rng = np.random.default_rng(4)
    n = 5
    ser = empty_series(np.arange(3) * 0.02, n)
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
    set_agent_rows(ser, 1, outs)
    for i, o in enumerate(outs):
        st = o.status
        assert np.array_equal(ser.u[1, i], o.u)
        assert np.array_equal(ser.lumped_est[1, i], o.lumped)
        assert ser.h_min[1, i] == st.h_min and ser.solve_us[1, i] == st.solve_us
        assert ser.fallback[1, i] == QPStatus(st.qp_status).degraded
        assert ser.input_clipped[1, i] == st.input_clipped
    assert not ser.fallback[0].any() and not ser.fallback[2].any()  # other rows untouched


# every field a run's agent rows fill (gcs.mission.run_output.set_agent_blocks)
_ROW_FIELDS = ("u", "lumped_est", "u_nom", "h_min", "solve_us", "clf_slack", "qp_relax",
               "u_corr", "fallback", "input_clipped", "alarms", "qp_status", "qp_active",
               "qp_kinds")


def _outputs(rng: np.random.Generator, n: int) -> list[AgentOutput]:
    """One step's outputs of ``n`` agents, every status field drawn (every QP status, active
    counts past the record's saturation, alarm and kind bits)."""
    outs = []
    for i in range(n):
        st = AgentStatus(
            Method.DCBF, qp_status=list(QPStatus)[int(rng.integers(len(QPStatus)))],
            solve_us=float(rng.uniform(0, 50)), h_min=[math.inf, float(rng.normal())][i % 2],
            slack=float(rng.uniform()), violation=float(rng.uniform()),
            input_clipped=bool(rng.random() < 0.5), alarms=int(rng.integers(0, 256)),
            active=ActiveRows(int(rng.integers(0, 400)), QPRow(int(rng.integers(0, 8)))),
            u_nom=rng.normal(size=3), correction=float(rng.uniform()))
        outs.append(AgentOutput(0.0, 0.0, 0.0, 0.0, np.zeros(4, np.float32), np.float32(0.5),
                                rng.normal(size=3), _estimate(rng, i + 1), st,
                                lumped=rng.normal(size=3)))
    return outs


def test_rows_written_in_blocks_equal_rows_written_one_by_one() -> None:
    """AgentRows, whose blocks end at every size from one row to past the run, writes what
    set_agent_rows writes row by row."""
    rng = np.random.default_rng(7)
    k, n = 11, 5
    steps = [_outputs(rng, n) for _ in range(k)]
    one = empty_series(np.arange(k) * 0.02, n)
    for r, outs in enumerate(steps):
        set_agent_rows(one, r, outs)
    assert one.qp_active.max() == 255 and one.fallback.any() and not one.fallback.all()
    for block in (1, 2, 3, 4, 11, 50):
        ser = empty_series(np.arange(k) * 0.02, n)
        rows = AgentRows(ser, n, block=block)
        for r, outs in enumerate(steps):
            rows.add(r, outs)
        rows.flush()
        for f in _ROW_FIELDS:
            assert np.array_equal(getattr(ser, f), getattr(one, f)), (block, f)


def test_agent_rows_refuse_a_row_out_of_order() -> None:
    rng = np.random.default_rng(8)
    rows = AgentRows(empty_series(np.arange(4) * 0.02, 2), 2, block=3)
    rows.add(0, _outputs(rng, 2))
    with pytest.raises(ValueError, match="row 2 after 0"):
        rows.add(2, _outputs(rng, 2))


@pytest.mark.parametrize("method", [Method.DCBF, Method.RCBF])
def test_a_run_records_in_blocks_what_it_records_row_by_row(
    method: Method, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run's rows written in blocks equal its rows written as each step ends: no agent
    writes an output after returning it (the QP's times aside, which are wall clock)."""
    blocks = run_inproc(SC, method, duration=1.5).series
    monkeypatch.setattr(run_output, "MAX_STAGED_STEPS", 1)
    rows = run_inproc(SC, method, duration=1.5).series
    assert len(blocks.t) == 75 and AgentRows(empty_series(blocks.t, SC.n), SC.n).block == 1
    for f in _ROW_FIELDS:
        if f != "solve_us":
            assert np.array_equal(getattr(blocks, f), getattr(rows, f), equal_nan=True), f


def test_no_agent_writes_an_estimate_it_published(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every estimate an agent returned holds, at the end of the run, the values it held
    when its step returned (a follower publishes its DESO's arrays without copies)."""
    seen: list[tuple[NeighbourEstimate, list[np.ndarray]]] = []
    batch = shards.published_batch

    def kept(ests: list[NeighbourEstimate]) -> EstimateBatch:
        seen.extend((e, [e.z1.copy(), e.z2.copy(), e.z3.copy(), e.xi.copy()]) for e in ests)
        return batch(ests)

    monkeypatch.setattr(shards, "published_batch", kept)
    run_inproc(SC, Method.DCBF, duration=1.0)
    assert len(seen) == (1 + 50) * SC.n
    for e, values in seen:
        for now, then in zip((e.z1, e.z2, e.z3, e.xi), values, strict=True):
            assert np.array_equal(now, then)


@pytest.mark.full
def test_followers_given_the_batch_equal_followers_given_dicts() -> None:
    """A follower handed the runner's batch of every agent's estimates (published_batch)
    flies the same bits as one handed its peers' estimates one by one (round_estimates,
    what a daemon receives), through an outage where the batch gives nothing and the dict
    is empty. Truth moves on a fixed path (the agents' commands do not act on it), so
    every step is compared on the same inputs."""
    from gcs.mission.agents.wire_form import published_batch
    from offboard.agent.factory import make_agent
    from offboard.agent.peers import peer_ids
    from offboard.estimation.bearing import formation_from_scenario

    form = formation_from_scenario(SC)
    pair = [[make_agent(SC, a.id, method="dcbf", form=form) for a in SC.agents] for _ in (0, 1)]
    by_batch, by_dict = pair
    p0 = SC.initial_positions()
    dt = SC.control_dt
    pub_batch = published_batch([ag.initial_estimate() for ag in by_batch])
    pub_dict = {e.id: e for e in round_estimates([ag.initial_estimate() for ag in by_dict])}
    compared = 0
    for k in range(120):
        t = k * dt
        tp = (p0 + 0.3 * np.sin(0.5 * t + np.arange(SC.n))[:, None]).astype(np.float32)
        tv = np.full_like(tp, 0.1)
        comm = not 40 <= k < 60
        outs_b = [ag.step(k, t, tp, tv, pub_batch, comm) for ag in by_batch]
        outs_d = [ag.step(k, t, tp, tv, {j: pub_dict[j] for j in peer_ids(form, ag.id)}
                          if comm else {}, comm) for ag in by_dict]
        for ob, od in zip(outs_b, outs_d, strict=True):
            assert np.array_equal(ob.q_ned, od.q_ned) and ob.thrust_norm == od.thrust_norm
            for f in ("z1", "z2", "z3", "xi"):
                assert np.array_equal(getattr(ob.estimate, f), getattr(od.estimate, f)), (k, f)
            compared += 1
        pub_batch = published_batch([o.estimate for o in outs_b])
        pub_dict = {e.id: e for e in round_estimates([o.estimate for o in outs_d])}
    assert compared == 120 * SC.n


def test_published_batch_keeps_each_cooperative_flag() -> None:
    """The in-process batch carries each estimate's ``cooperative`` flag as the wire does
    (offboard.daemon.wire_convert.put_row): a non-cooperative follower's initial estimate
    already gets the others' full share against it, in process as in a distributed run."""
    from gcs.mission.agents.wire_form import published_batch

    rng = np.random.default_rng(5)
    ests = [_estimate(rng, aid) for aid in range(1, 10)]
    b = published_batch(ests)
    assert b.cooperative.tolist() == [e.cooperative for e in ests]
    assert not b.cooperative.all()
    assert b.leader.tolist() == [e.is_leader for e in ests]
