"""Safety filters by method (offboard.safety.filter), the method switch, the dropout hold."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from reference.clf_rows import clf_terms

from offboard.agent.factory import FollowerAgent, LeaderAgent, make_agent
from offboard.estimation.sensing import DropoutHold
from offboard.safety.apf import ApfFilter, NoFilter
from offboard.safety.base import SafetyInput, saturate_norm
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.filter import SAFETY_FILTERS, make_filters, parse_method
from offboard.safety.rcbf.filter import RcbfFilter
from swarm_common.enums import Method, QPStatus
from swarm_common.scenario.model import load_scenario, with_overrides

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"
LO, HI = np.full(3, -3.0), np.full(3, 3.0)


@pytest.fixture(scope="module")
def sc():
    return load_scenario(CUBE8)


def _input(dp: np.ndarray, dv: np.ndarray, pairs: list[int]) -> SafetyInput:
    clf = clf_terms(np.array([-0.5, 0, 0]), np.zeros(3), np.zeros(3), np.zeros(3),
                    1.0, 1.0, 1.0, 1.0)
    return SafetyInput(clf, np.zeros(3), np.zeros(3), dp, dv, np.array(pairs, dtype=int), {})


def _filters(sc, mask: np.ndarray) -> dict:
    """make_filters, with the dcbf filter configured for the scenario's vehicle."""
    filters = make_filters(sc.controller, LO, HI, mask)
    dcbf = filters[Method.DCBF]
    assert isinstance(dcbf, DcbfFilter)
    dcbf.configure(sc.vehicle, sc.control_dt)
    return filters


def test_dcbf_needs_configure(sc) -> None:
    filt = make_filters(sc.controller, LO, HI, np.zeros(sc.n, dtype=bool))[Method.DCBF]
    with pytest.raises(RuntimeError, match="configure"):
        filt.apply(_input(np.zeros((0, 3)), np.zeros((0, 3)), []))


def test_every_method_has_exactly_its_filter() -> None:
    assert set(SAFETY_FILTERS) == set(Method)
    assert SAFETY_FILTERS[Method.RCBF] is RcbfFilter
    assert SAFETY_FILTERS[Method.APF] is ApfFilter
    assert SAFETY_FILTERS[Method.NONE] is NoFilter
    for m, cls in SAFETY_FILTERS.items():
        assert cls.method is m


def test_parse_method_accepts_member_or_string_and_rejects_others() -> None:
    assert parse_method("apf") is Method.APF
    assert parse_method(Method.RCBF) is Method.RCBF
    with pytest.raises(ValueError, match="unknown method 'cbf'; use one of rcbf, dcbf, apf, none"):
        parse_method("cbf")


def test_set_method_switches_and_validates(sc) -> None:
    fol = make_agent(sc, sc.follower_ids[0], method="none")
    lead = make_agent(sc, sc.leader_ids[0], method=Method.APF)
    assert isinstance(fol, FollowerAgent) and isinstance(lead, LeaderAgent)
    assert fol.method is Method.NONE and lead.method is Method.APF
    fol.set_method("rcbf")
    assert fol.method is Method.RCBF
    with pytest.raises(ValueError):
        fol.set_method("fast")
    with pytest.raises(ValueError):
        make_agent(sc, sc.leader_ids[0], method="fast")
    assert fol.method is Method.RCBF


def test_filters_without_pairs_return_the_clipped_nominal(sc) -> None:
    mask = np.zeros(sc.n, dtype=bool)
    x = _input(np.zeros((0, 3)), np.zeros((0, 3)), [])
    u_ref = np.clip(x.clf.u_nom, LO, HI)
    for m, filt in _filters(sc, mask).items():
        res = filt.apply(x)
        assert np.array_equal(res.u, u_ref), m
        assert res.h_min == np.inf and res.qp_status is QPStatus.INACTIVE and not res.fallback


def test_close_pair_changes_control_for_rcbf_and_apf_only(sc) -> None:
    mask = np.zeros(sc.n, dtype=bool)
    filters = make_filters(sc.controller, LO, HI, mask)
    # agent j 0.5 m ahead along +x, closing at 1 m/s: the nominal pushes towards it
    x = _input(np.array([[-0.5, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), [1])
    u_none = filters[Method.NONE].apply(x)
    u_apf = filters[Method.APF].apply(x)
    u_rcbf = filters[Method.RCBF].apply(x)
    assert u_none.h_min == u_apf.h_min == u_rcbf.h_min < 0.0
    assert u_apf.u[0] < u_none.u[0] and u_rcbf.u[0] < u_none.u[0]
    assert u_rcbf.qp_status in (QPStatus.SOLVED, QPStatus.RELAXED)
    assert u_rcbf.qp_status == str(u_rcbf.qp_status)  # the wire string


def test_rcbf_needs_a_positive_tau(sc) -> None:
    ctl = with_overrides(sc, controller={"tau_safe_s": 0.0}).controller
    with pytest.raises(ValueError, match="tau_safe_s"):
        RcbfFilter(ctl, LO, HI, np.zeros(sc.n, dtype=bool))


def test_saturate_norm_of_random_vectors_and_other_shapes() -> None:
    """The 3-vector path (in-order sum in Python floats) against numpy's norm, over
    magnitudes from 1e-6 to 1e6 on both sides of the bound; other shapes and float32."""
    rng = np.random.default_rng(17)
    for _ in range(2000):
        x = rng.normal(0.0, 1.0, 3) * 10.0 ** rng.uniform(-6.0, 6.0)
        bound = float(10.0 ** rng.uniform(-6.0, 6.0))
        n = float(np.linalg.norm(x))
        got = saturate_norm(x, bound)
        if n > bound:
            assert np.allclose(got, x * (bound / n), rtol=1e-15, atol=0.0)
            assert math.isclose(float(np.linalg.norm(got)), bound, rel_tol=1e-14)
        else:
            assert got is x
    y = np.array([3.0, 4.0, 0.0, 12.0])
    assert np.allclose(saturate_norm(y, 6.5), y / 2.0)
    z = np.array([3.0, 4.0, 0.0], dtype=np.float32)
    assert np.allclose(saturate_norm(z, 1.0), [0.6, 0.8, 0.0])


def test_saturate_norm() -> None:
    x = np.array([3.0, 4.0, 0.0])
    assert np.allclose(saturate_norm(x, 1.0), [0.6, 0.8, 0.0])
    assert saturate_norm(x, 10.0) is x


def test_dropout_hold_extrapolates_a_dropped_pair() -> None:
    hold = DropoutHold(3, 0, 0.2, enabled=True)
    rp = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.0, 2, 0]])
    rv = np.array([[0.0, 0, 0], [-1.0, 0, 0], [0.0, 0, 0]])
    valid = np.array([False, True, True])
    sel, _, _ = hold.pairs(0.0, valid, rp, rv)
    assert list(sel) == [1, 2]
    # pair 1 dropped 0.1 s later: still constrained, moved on by its last relative velocity
    sel, rp2, rv2 = hold.pairs(0.1, np.array([False, False, True]), rp, rv)
    assert list(sel) == [1, 2] and np.allclose(rp2[1], [0.9, 0, 0]) and np.allclose(rv2[1], rv[1])
    # after the hold time it is gone
    sel, _, _ = hold.pairs(0.3, np.array([False, False, True]), rp, rv)
    assert list(sel) == [2]
    off = DropoutHold(3, 0, 0.2, enabled=False)
    off.pairs(0.0, valid, rp, rv)
    sel, rp3, _ = off.pairs(0.1, np.array([False, False, True]), rp, rv)
    assert list(sel) == [2] and rp3 is rp
    # disabled, it keeps no per-agent state at all
    assert off._last_seen.size == off._last_rp.size == off._last_rv.size == 0
