"""The dcbf filter's fallback: a step whose rows are not finite brakes on −w − 2 z2,
projected into the realisable input set (offboard.dcbf_qp.DcbfQP.solve). The brake is
formed only when the fallback is taken; this checks it is still the right one."""

from __future__ import annotations

import numpy as np
from conftest import CUBE8

from offboard.clf_rcbf import ClfTerms
from offboard.dcbf_filter import DcbfFilter
from offboard.safety_filter import SafetyInput
from swarm_common.scenario import load_scenario


def _filter() -> DcbfFilter:
    sc = load_scenario(CUBE8)
    ctl = sc.controller
    box = np.full(3, ctl.u_max_mps2)
    f = DcbfFilter(ctl, -box, box, np.zeros(sc.n, dtype=bool))
    f.configure(sc.vehicle, sc.control_dt)
    return f


def _input(dp: np.ndarray, w: np.ndarray, z2: np.ndarray) -> SafetyInput:
    m = len(dp)
    clf = ClfTerms(V=0.5, lfv=-0.1, lgv=np.array([0.1, 0.0, 0.2]), u_nom=np.array([0.3, 0.1, 0.0]))
    return SafetyInput(
        clf, w, z2, dp, np.zeros((m, 3)), np.arange(1, m + 1), {}, other_acc=np.zeros((m, 3)),
        full_share=np.zeros(m, dtype=bool), margin=np.zeros(m),
        predicted=np.zeros(m, dtype=bool),
    )


def test_non_finite_rows_brake_on_the_disturbance_and_velocity() -> None:
    f = _filter()
    assert f.qp is not None
    w, z2 = np.array([0.4, -0.2, 0.1]), np.array([1.0, 0.5, -0.3])
    dp = np.array([[0.5, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    out = f.apply(_input(dp, w, z2))
    assert out.fallback
    want = f.qp.uset.project(-w - f.brake_gain * z2)
    assert np.array_equal(out.u, want)
    assert np.isfinite(out.u).all()


def test_finite_rows_take_no_fallback() -> None:
    f = _filter()
    out = f.apply(_input(np.array([[3.0, 0.0, 0.0]]), np.zeros(3), np.zeros(3)))
    assert not out.fallback
    assert np.isfinite(out.u).all()
