"""The safety filters' fallback: a step whose rows are not finite brakes on −w − 2 z2,
projected into the realisable input set (dcbf, offboard.safety.dcbf.qp.DcbfQP.solve) or clipped
to the box (rcbf, offboard.safety.rcbf.clf_rcbf.SafetyQP.solve). The filters form the brake only
when
the fallback is taken (offboard.safety.rcbf.clf_rcbf.fallback_of); this checks it is still the
right one."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from conftest import CUBE8

from offboard.safety.base import SafetyInput
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from offboard.safety.rcbf.filter import RcbfFilter
from swarm_common.scenario.model import load_scenario

SC = load_scenario(CUBE8)
BOX = np.full(3, SC.controller.u_max_mps2)


def _dcbf() -> DcbfFilter:
    f = DcbfFilter(SC.controller, -BOX, BOX, np.zeros(SC.n, dtype=bool))
    f.configure(SC.vehicle, SC.control_dt)
    return f


def _rcbf() -> RcbfFilter:
    return RcbfFilter(SC.controller, -BOX, BOX, np.zeros(SC.n, dtype=bool))


def _input(dp: np.ndarray, w: np.ndarray, z2: np.ndarray) -> SafetyInput:
    m = len(dp)
    clf = ClfTerms(V=0.5, lfv=-0.1, lgv=np.array([0.1, 0.0, 0.2]), u_nom=np.array([0.3, 0.1, 0.0]))
    return SafetyInput(
        clf, w, z2, dp, np.zeros((m, 3)), np.arange(1, m + 1), {}, other_acc=np.zeros((m, 3)),
        full_share=np.zeros(m, dtype=bool), margin=np.zeros(m),
        predicted=np.zeros(m, dtype=bool),
    )


def test_dcbf_non_finite_rows_brake_on_the_disturbance_and_velocity() -> None:
    f = _dcbf()
    assert f.qp is not None
    w, z2 = np.array([0.4, -0.2, 0.1]), np.array([1.0, 0.5, -0.3])
    dp = np.array([[0.5, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    out = f.apply(_input(dp, w, z2))
    assert out.fallback
    assert np.array_equal(out.u, f.qp.uset.project(-w - f.brake_gain * z2))


def test_rcbf_non_finite_rows_brake_on_the_disturbance_and_velocity() -> None:
    f = _rcbf()
    w, z2 = np.array([0.4, -0.2, 0.1]), np.array([5.0, 0.5, -0.3])  # x clipped to the box
    dp = np.array([[0.5, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    out = f.apply(_input(dp, w, z2))
    assert out.fallback
    want = np.clip(-w - f.qp.brake_gain * z2, -BOX, BOX)
    assert np.array_equal(out.u, want)
    assert want[0] == -BOX[0]


@pytest.mark.parametrize("make", [_dcbf, _rcbf])
def test_finite_rows_take_no_fallback(make: Callable[[], DcbfFilter | RcbfFilter]) -> None:
    f = make()
    out = f.apply(_input(np.array([[3.0, 0.0, 0.0]]), np.zeros(3), np.zeros(3)))
    assert not out.fallback
    assert np.isfinite(out.u).all()
