"""The dcbf filter's span over missed control periods (DcbfFilter.set_span): its
relative-acceleration difference divides by the time since the step before
(tests/integration/inproc/test_missed_steps_dcbf.py flies a starved swarm with it)."""

from __future__ import annotations

from conftest import CUBE8

from offboard.agent.factory import FollowerAgent, make_agent
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.step_kernel import P_DT
from swarm_common.enums import Method
from swarm_common.scenario.model import load_scenario


def test_span_scales_the_relative_acceleration_difference() -> None:
    """The filter's finite difference of Δv: the same change of relative velocity over
    one period, or over three with set_span(3), gives a relative acceleration 3× apart;
    set_span(1) restores the period exactly (the in-process bits)."""
    sc = load_scenario(CUBE8)
    ag = make_agent(sc, 3, seed=1, method="dcbf")
    assert isinstance(ag, FollowerAgent)
    filt = ag.filters[Method.DCBF]
    assert isinstance(filt, DcbfFilter)
    dt = sc.control_dt
    params = filt.rows_state()[0]
    assert params[P_DT] == dt
    filt.set_span(3)
    assert params[P_DT] == 3 * dt
    filt.set_span(1)
    assert params[P_DT] == dt  # exactly: in-process and lockstep runs keep their bits
    filt.forget_history()
    assert not filt.rows_state()[4].any()
