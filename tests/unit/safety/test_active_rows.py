"""The safety filter's report for the record (docs/records.md): the QP's rows active at its
solution (offboard.records.ActiveRows) and the correction ‖u − u_nom‖, checked numerically
on two followers heading at each other, where a pair's barrier row binds: the reported
rows are tight at the solution (constraint value ~ 0), the others are not, u ≠ u_nom."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from conftest import CUBE8

from offboard.agent.factory import FollowerAgent, make_agent
from offboard.records import NO_ACTIVE, AgentStatus
from offboard.safety.base import SafetyInput
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.rcbf import clf_rcbf
from offboard.safety.rcbf.clf_rcbf import ACTIVE_TOL_MPS2, ClfTerms
from offboard.safety.rcbf.filter import RcbfFilter
from swarm_common.enums import Method, QPRow, QPStatus
from swarm_common.scenario.model import load_scenario

pytestmark = pytest.mark.unit
SC = load_scenario(CUBE8)
J = 4  # the other follower's scenario index


def _head_on(dp: float = -2.5, dv: float = 1.0, ux: float = 3.0) -> SafetyInput:
    """Follower i at the origin flying +x at dv/2 m/s, follower j ``-dp`` m ahead flying
    −x at dv/2 (Δp = p_i − p_j, Δv = v_i − v_j: closing at dv m/s), u_nom speeding up
    towards it (``ux`` m/s²); the CLF row off (L_gV = 0). The defaults break both of the
    pair's rows (a solver answers), (−3, 0.3, 1.5) only one (the exact one-row solution)."""
    clf = ClfTerms(V=0.0, lfv=0.0, lgv=np.zeros(3), u_nom=np.array([ux, 0.4, 0.0]))
    return SafetyInput(clf, np.zeros(3), np.array([dv / 2, 0.0, 0.0]),
                       np.array([[dp, 0.0, 0.0]]), np.array([[dv, 0.0, 0.0]]), np.array([J]),
                       {})


def _two_head_on() -> SafetyInput:
    """Two of them, one along x and one along y, and a CLF row that pulls towards both
    (L_gV = (−1, −1, 0)): the barrier rows of both pairs bind, and the CLF row with a
    slack."""
    clf = ClfTerms(V=0.0, lfv=0.0, lgv=np.array([-1.0, -1.0, 0.0]),
                   u_nom=np.array([3.0, 3.0, 0.0]))
    return SafetyInput(clf, np.zeros(3), np.array([0.5, 0.5, 0.0]),
                       np.array([[-2.5, 0.0, 0.0], [0.0, -2.5, 0.0]]),
                       np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([J, J + 1]), {})


def _follower(method: str) -> FollowerAgent:
    ag = make_agent(SC, 3, seed=1, method=method)
    assert isinstance(ag, FollowerAgent)
    return ag


@pytest.mark.parametrize("case", ["one_pair_exact", "one_pair", "two_pairs_clf"])
def test_dcbf_head_on_reports_the_tight_pair_rows_and_the_correction(
    case: str, monkeypatch: pytest.MonkeyPatch,
) -> None:
    solves: list[int] = []
    real_solve = clf_rcbf.daqp_solve

    def counted(*a: Any, **kw: Any) -> Any:
        solves.append(1)
        return real_solve(*a, **kw)

    monkeypatch.setattr(clf_rcbf, "daqp_solve", counted)
    ag = _follower("dcbf")
    filt = ag.filters[Method.DCBF]
    assert isinstance(filt, DcbfFilter) and filt.qp is not None
    two = case == "two_pairs_clf"
    x = {"one_pair_exact": _head_on(-3.0, 0.3, 1.5), "one_pair": _head_on(),
         "two_pairs_clf": _two_head_on()}[case]
    u_nom = x.clf.u_nom.copy()
    res = filt.apply(x)
    assert res.qp_status is QPStatus.SOLVED
    assert (len(solves) == 0) == (case == "one_pair_exact")  # the exact path, or DAQP
    u = res.u
    assert np.linalg.norm(u - u_nom) > 0.5  # the filter changed the command
    # the rows as the QP saw them: per pair a (C1) row, then per pair a (C2) row, unit
    # normals, g u ≥ r
    m = len(x.pairs)
    g, rhs = filt.rows_out()[:2]
    value = g[:2 * m] @ u - rhs[:2 * m]  # m/s², ≥ 0 when kept, 0 when tight
    assert value.min() >= -1e-9
    tight = value <= ACTIVE_TOL_MPS2
    assert abs(value[tight]).max() < 1e-6  # the binding rows hold with equality
    bound = sorted({int(x.pairs[r % m]) for r in np.flatnonzero(tight)})
    assert bound == sorted(x.pairs.tolist())  # every pair's row binds
    assert QPRow.PAIR in res.active.kinds and sorted(res.active.pairs) == bound
    # the count: the tight pair rows, the input polytope's bounds at u, the CLF row
    qp = filt.qp
    y = qp.a_u @ u
    n_input = int(np.sum((y >= qp.hi_u - ACTIVE_TOL_MPS2) | (y <= qp.lo_u + ACTIVE_TOL_MPS2)))
    assert (QPRow.INPUT in res.active.kinds) == (n_input > 0)
    assert (QPRow.CLF in res.active.kinds) == two == (res.slack > 1.0)
    assert res.active.count == int(tight.sum()) + n_input + int(two)
    # the follower's status: u_nom, the active rows and ‖u − u_nom‖ of the filter's u
    st = AgentStatus(Method.DCBF, u_nom=x.clf.u_nom)
    out = ag._use_filter_output(res, np.zeros(3), st)
    assert out is u and st.active is res.active and st.qp_status is QPStatus.SOLVED
    assert np.array_equal(st.u_nom, u_nom) and st.slack == res.slack
    assert st.correction == pytest.approx(float(np.linalg.norm(u - u_nom)), rel=0, abs=1e-12)


def test_rcbf_head_on_reports_the_tight_pair_row() -> None:
    ag = _follower("rcbf")
    filt = ag.filters[Method.RCBF]
    assert isinstance(filt, RcbfFilter)
    x = _head_on()
    res = filt.apply(x)
    assert res.qp_status is QPStatus.SOLVED
    assert QPRow.PAIR in res.active.kinds and res.active.pairs == (J,)
    # the one RCBF row (row 1 of the QP as it was solved: n̂ᵀu + σ ≥ r, n̂ = Δp/‖Δp‖ = −x)
    # is tight at u, which cuts u_x back; nothing else binds
    qp = filt.qp
    np.testing.assert_allclose(qp._a[1, :3], [-1.0, 0.0, 0.0], rtol=0, atol=1e-12)
    assert abs(qp._a[1, :3] @ res.u - qp.l[1]) < 1e-6
    assert res.u[0] < x.clf.u_nom[0] - 1.0
    assert res.active.count == 1 and res.active.kinds == QPRow.PAIR


def test_no_rows_are_active_when_the_nominal_input_keeps_every_row() -> None:
    ag = _follower("dcbf")
    filt = ag.filters[Method.DCBF]
    # flying apart, far outside D: u_nom keeps every row, the QP's shortcut answers
    x = _head_on(-6.0, -4.0, 0.5)
    res = filt.apply(x)
    assert res.qp_status is QPStatus.INACTIVE and res.active is NO_ACTIVE
    st = AgentStatus(Method.DCBF, u_nom=x.clf.u_nom)
    ag._use_filter_output(res, np.zeros(3), st)
    assert st.correction == 0.0 and st.active.count == 0
