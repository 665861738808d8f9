"""The daemon's wire records keep their strings (roles, method, QP status, health)."""

from __future__ import annotations

import numpy as np

from offboard.daemon.mavlink.odometry import Odometry
from offboard.daemon.wire_convert import (
    estimate_to_wire,
    estimates_from_wire,
    measured_state,
    status_to_wire,
)
from offboard.records import AgentOutput, AgentStatus, NeighbourEstimate
from swarm_common import wire
from swarm_common.enums import Method, QPStatus


def _est(leader: bool) -> NeighbourEstimate:
    xi = np.arange(12.0)
    return NeighbourEstimate(2, 0.5, np.ones(3), np.zeros(3), np.zeros(3), xi, leader)


def test_estimate_round_trip_keeps_the_role() -> None:
    for leader, role in ((True, "leader"), (False, "follower")):
        w = estimate_to_wire(_est(leader), 7, None)
        back = wire.decode(wire.encode(w))
        assert isinstance(back, wire.Estimate) and back.role == role
        assert bool(estimates_from_wire({2: 0}, 1, {2: back}).leader[0]) is leader


def test_estimate_round_trip_keeps_cooperation() -> None:
    for cooperative in (True, False):
        e = _est(False)
        e.cooperative = cooperative
        back = wire.decode(wire.encode(estimate_to_wire(e, 7, None)))
        assert isinstance(back, wire.Estimate)
        assert bool(estimates_from_wire({2: 0}, 1, {2: back}).cooperative[0]) is cooperative


def test_received_payloads_as_one_batch() -> None:
    """estimates_from_wire: each decoded payload's vectors, stamp and flags in its agent's
    row, ids outside the scenario left out, agents not received NaN-stamped; a payload
    built without its block as well."""
    rng = np.random.default_rng(2)
    sent = {}
    flags = ((4, True, True), (9, False, False), (7, False, True), (50, False, True))
    flags_of = {aid: (leader, coop) for aid, leader, coop in flags}
    for aid, leader, coop in flags:
        e = NeighbourEstimate(aid, 0.02 * aid, rng.normal(size=3), rng.normal(size=3),
                              rng.normal(size=3), rng.normal(size=12), leader, coop)
        back = wire.decode(wire.encode(estimate_to_wire(e, 3, rng.normal(size=6))))
        assert isinstance(back, wire.Estimate)
        sent[aid] = back
    sent[7].block = None  # a payload made in process, not decoded
    index_of = {4: 0, 7: 1, 8: 2, 9: 3}
    b = estimates_from_wire(index_of, 4, sent)
    assert np.isnan(b.t[2])
    for aid, j in ((4, 0), (7, 1), (9, 3)):
        got = sent[aid]
        assert b.t[j] == got.t
        assert np.array_equal(b.rows[j], np.concatenate([got.z1, got.z2, got.z3, got.xi]))
        assert b.leader[j] == (got.role == "leader") and b.cooperative[j] == got.cooperative
        assert b.leader[j] == flags_of[aid][0] and b.cooperative[j] == flags_of[aid][1]


def test_measured_state_is_enu_and_carried_one_step() -> None:
    # yaw 90° in NED (nose east): body forward = NED east = ENU x
    c = float(np.sqrt(0.5))
    odo = Odometry(0, 1.0, 2.0, -3.0, 0.0, (c, 0.0, 0.0, c), (2.0, 0.0, -1.0))
    got = measured_state(odo, 0.1)
    assert got is not None
    p, v = got
    np.testing.assert_allclose(v, [2.0, 0.0, 1.0], atol=1e-12)  # east 2, climbing 1
    np.testing.assert_allclose(p, [2.0 + 0.2, 1.0, 3.0 + 0.1], atol=1e-12)
    bad = Odometry(0, float("nan"), 2.0, -3.0, 0.0, (c, 0.0, 0.0, c), (0.0, 0.0, 0.0))
    assert measured_state(bad, 0.1) is None
    assert measured_state(Odometry(0, 0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0, 0.0)), 0.1) is None


def test_status_strings_and_health() -> None:
    st = AgentStatus(method=Method.RCBF, qp_status=QPStatus.RELAXED, fallbacks=1)
    out = AgentOutput(0.0, 0.0, 0.0, 1.0, np.array([1, 0, 0, 0], np.float32), np.float32(0.3),
                      np.zeros(3), _est(False), st)
    s = status_to_wire(4, 3, 0.06, out, "OFFBOARD", True)
    assert s.est_health == "qp-fallback"
    assert np.array_equal(s.p_des, [0.0, 1.0, 2.0])  # ξ's p* part
    back = wire.decode(wire.encode(s))
    assert isinstance(back, wire.Status)
    assert (back.method, back.qp_status) == ("rcbf", "relaxed")
    st.qp_status = QPStatus.SOLVED
    assert status_to_wire(4, 3, 0.06, out, "OFFBOARD", True).est_health == "ok"
    assert status_to_wire(4, 3, 0.06, out, "OFFBOARD", False).est_health == "predicting"
