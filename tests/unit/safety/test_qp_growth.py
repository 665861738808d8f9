"""Safety QPs that start small and grow on demand
(offboard.safety.rcbf.clf_rcbf._ClfRowsQP.fit_rows):
a grown problem answers what a problem built at full size answers, every row is kept, and
the growth stops at the limit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from reference.clf_rows import clf_terms, rcbf_rows

from offboard.safety.dcbf.filter import input_set_of
from offboard.safety.dcbf.qp import DcbfQP
from offboard.safety.rcbf.clf_rcbf import ClfTerms, SafetyQP
from swarm_common.scenario.model import load_scenario

SC = load_scenario(Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml")
VEH, CTL = SC.vehicle, SC.controller

LO = np.array([-3.2, -3.2, -8.0])
HI = np.array([3.2, 3.2, 8.0])


def _rcbf_case(rng: np.random.Generator, m: int):  # type: ignore[no-untyped-def]
    dp = rng.normal(0, 1.2, (m, 3))
    dv = rng.normal(0, 1.0, (m, 3))
    w = rng.normal(0, 0.3, 3)
    n_hat, rhs, h = rcbf_rows(dp, dv, w, np.zeros((m, 3)), np.full(m, 0.5), 0.8, 0.5, 0.6)
    clf = clf_terms(rng.normal(0, 1, 3), rng.normal(0, 1, 3), w, np.zeros(3), 0.5, 0.1, 1.0,
                    2.0)
    return n_hat, rhs, h, clf, w


def test_rcbf_qp_grows_and_matches_a_full_size_problem() -> None:
    rng = np.random.default_rng(5)
    compared = 0
    for _ in range(60):
        m = int(rng.integers(5, 15))
        n_hat, rhs, h, clf, w = _rcbf_case(rng, m)
        small = SafetyQP(2, LO, HI, rho=10.0, clf_c=1.0, limit=20)
        full = SafetyQP(20, LO, HI, rho=10.0, clf_c=1.0)
        a = small.solve(clf.u_nom, clf, n_hat, rhs, h, brake=-w)
        b = full.solve(clf.u_nom, clf, n_hat, rhs, h, brake=-w)
        assert a.status == b.status
        if a.status == "inactive":
            assert np.array_equal(a.u, b.u)
            continue
        compared += 1
        assert small.m >= m  # grown: no row was dropped
        assert np.allclose(a.u, b.u, atol=2e-3)
        # every row of the problem holds (up to the relaxation and OSQP's tolerance)
        assert np.all(n_hat @ a.u + a.violation >= rhs - 2e-3)
    assert compared > 10


def test_growth_stops_at_the_limit() -> None:
    rng = np.random.default_rng(8)
    n_hat, rhs, h, clf, w = _rcbf_case(rng, 12)
    qp = SafetyQP(2, LO, HI, rho=10.0, clf_c=1.0, limit=6)
    qp.fit_rows(12)
    assert qp.m == 6
    qp.fit_rows(3)
    assert qp.m == 6  # never shrinks


def test_dcbf_qp_grows_and_keeps_every_row() -> None:
    uset = input_set_of(CTL, VEH)
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(40):
        k = int(rng.integers(6, 20))
        g = rng.normal(0, 1, (k, 3))
        g /= np.linalg.norm(g, axis=1)[:, None]
        rhs = rng.normal(-2.0, 1.0, k)
        u_nom = rng.normal(0, 3, 3)
        clf = ClfTerms(V=0.0, lfv=0.0, lgv=np.zeros(3), u_nom=u_nom)
        small = DcbfQP(4, uset, CTL.rho, CTL.clf_c, limit=24)
        full = DcbfQP(24, uset, CTL.rho, CTL.clf_c)
        a = small.solve(u_nom, clf, g, rhs, 1.0, np.zeros(3))
        b = full.solve(u_nom, clf, g, rhs, 1.0, np.zeros(3))
        assert a.status == b.status
        assert uset.contains(a.u, tol=1e-6)
        if a.status in ("solved", "inactive"):
            checked += 1
            assert np.all(g @ a.u >= rhs - 2e-3)
            assert np.allclose(a.u, b.u, atol=2e-3)
    assert checked > 10
