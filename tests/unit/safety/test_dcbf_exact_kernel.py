"""The DCBF QP's compiled pre-solve step (offboard.safety.dcbf.exact_kernel.pre_solve_kernel)
against the numpy formulation it replaced, written out here as the reference: the CLF
row's bound from the projected nominal input, and the exact solution with one active
barrier row, alone or with the CLF row. Within rounding (``tests/reference/close.py``: two
implementations may sum in different orders), on random problems that take every
branch (no row violated, two violated, one violated with and without the CLF row, a
multiplier of the wrong sign, a row of non-unit length, the input set broken, an L_gV
too small to normalise)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from reference.close import assert_close

from offboard.safety.dcbf.exact_kernel import NO_EXACT, pre_solve_kernel
from offboard.safety.dcbf.filter import input_set_of
from offboard.safety.dcbf.kernel import rows_hold_kernel
from swarm_common.scenario.model import load_scenario

SC = load_scenario(Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml")
RHO = SC.controller.rho
CLF_C = SC.controller.clf_c
LIN_SIGMA = max(1e3, 50.0 * RHO)
TINY_LGV_SEEN: list[int] = []  # the reference's branch of a vanishing L_gV, when taken


def _reference(u_nom, g, rhs, k, lgv, lfv, v, uset, a_u, lo_u, hi_u):  # type: ignore[no-untyped-def]
    """The numpy formulation (DcbfQP.solve before the kernel): (clf_rhs, (u, δ) or None)."""
    u_c = uset.project(u_nom)
    clf_rhs = max(-lfv - CLF_C * v, float(lgv.dot(u_c)))
    viol = rhs[:k] - g[:k] @ u_nom
    bad = np.flatnonzero(viol > 0.0)
    if len(bad) != 1:
        return clf_rhs, None
    j = int(bad[0])
    gj = g[j]
    if abs(float(gj.dot(gj)) - 1.0) > 1e-9:
        return clf_rhs, None
    lam = float(viol[j]) + 1e-9
    u = u_nom + lam * gj
    delta = 0.0
    if float(lgv.dot(u)) > clf_rhs:
        nrm = math.sqrt(float(lgv.dot(lgv)))
        if nrm <= 1e-9:
            TINY_LGV_SEEN.append(1)
            return clf_rhs, None
        a = lgv / nrm
        c = float(a.dot(gj))
        half_inv_rho = 0.5 / RHO
        nu = (float(a.dot(u_nom)) - clf_rhs / nrm + c * float(viol[j])) / (
            1.0 + half_inv_rho - c * c
        )
        if not nu >= 0.0:
            return clf_rhs, None
        lam = float(viol[j]) + nu * c + 1e-9
        u = u_nom - nu * a + lam * gj
        delta = nu * half_inv_rho
    if not 0.0 <= lam <= LIN_SIGMA:
        return clf_rhs, None
    if not rows_hold_kernel(a_u, lo_u, hi_u, g, rhs, k, u):
        return clf_rhs, None
    return clf_rhs, (u, delta)


@pytest.mark.full
def test_pre_solve_kernel_equals_the_numpy_formulation() -> None:
    uset = input_set_of(SC.controller, SC.vehicle)
    a_u, lo_u, hi_u = uset.rows()
    proj, cos_a, sin_a = uset.projection
    rng = np.random.default_rng(7)
    seen = {"none": 0, "exact": 0, "with_clf": 0}
    for trial in range(6000):
        u_nom = rng.normal(0.0, 3.0 if trial % 5 else 12.0, 3)  # sometimes outside the set
        m = int(rng.integers(1, 9))
        g = rng.normal(0.0, 1.0, (m, 3))
        g /= np.linalg.norm(g, axis=1)[:, None]
        if trial % 17 == 0:
            g[0] *= 1.0 + 1e-6  # not unit length
        rhs = g @ u_nom - rng.uniform(0.2, 3.0, m)
        for j in range(int(rng.integers(0, 3))):  # 0, 1 or 2 rows pushed past u_nom
            rhs[j % m] = float(g[j % m] @ u_nom) + rng.uniform(0.001, 2.0)
        k = m if trial % 7 else max(1, m - 1)
        lgv = rng.normal(0.0, 0.05 if trial % 2 else 2.0, 3)
        if trial % 29 == 0:
            lgv *= 1e-11  # ‖L_gV‖ below 1e-9: the CLF row cannot be normalised
        lfv, v = float(rng.normal(0.0, 1.0)), float(rng.uniform(0.0, 2.0))
        ref_rhs, ref = _reference(u_nom, g, rhs, k, lgv, lfv, v, uset, a_u, lo_u, hi_u)
        viol = rhs[:k] - g[:k] @ u_nom
        u = np.full(3, np.nan)
        clf_rhs, delta = pre_solve_kernel(
            u_nom, g, rhs, viol, k, lgv, lfv, v, CLF_C, 0.5 / RHO, LIN_SIGMA, a_u, lo_u, hi_u,
            proj, cos_a, sin_a, u,
        )
        # two implementations (kernel loops vs numpy's @): within rounding (close.py)
        assert_close(clf_rhs, ref_rhs, trial)
        if ref is None:
            assert delta == NO_EXACT, trial
            seen["none"] += 1
        else:
            assert_close(delta, ref[1], trial)
            assert_close(u, ref[0], (trial, u, ref))
            seen["exact"] += 1
            seen["with_clf"] += ref[1] > 0.0
    assert min(seen.values()) > 300, seen  # every branch taken often
    assert len(TINY_LGV_SEEN) > 10


def test_projection_keeps_points_inside_and_moves_none_strictly_inside() -> None:
    """InputSet.project through its array of projection scalars: every answer is in the
    set, a point strictly inside (10 shrinks from every side) is returned unchanged, and
    a second projection moves an answer by rounding at most."""
    uset = input_set_of(SC.controller, SC.vehicle)
    rng = np.random.default_rng(3)
    inside = 0
    for _ in range(4000):
        u = rng.normal(0.0, 6.0, 3)
        p = uset.project(u)
        assert uset.contains(p, tol=1e-9)
        assert np.allclose(uset.project(p), p, rtol=0.0, atol=1e-12)
        a_u, lo_u, hi_u = uset.rows()
        y = a_u @ u
        if (y <= hi_u - 10 * uset.shrink).all() and (y >= lo_u + 10 * uset.shrink).all():
            inside += 1
            assert np.array_equal(p, u)
    assert inside > 500
