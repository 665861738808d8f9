"""The daemon's wire records keep their strings (roles, method, QP status, health)."""

from __future__ import annotations

import numpy as np

from offboard.agent_types import AgentOutput, AgentStatus, NeighbourEstimate
from offboard.daemon import estimate_from_wire, estimate_to_wire, status_to_wire
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
        assert estimate_from_wire(back).is_leader is leader


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
