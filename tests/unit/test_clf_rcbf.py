"""CLF–RCBF QP (paper §4.2–4.4; Departures 10–14): constraints checked independently of OSQP."""

import numpy as np

from offboard.apf import apf_term
from offboard.clf_rcbf import SafetyQP, barrier, clf_terms, rcbf_rows

LO = np.array([-3.2, -3.2, -8.0])
HI = np.array([3.2, 3.2, 8.0])


def _case(rng, m):
    dp = rng.normal(0, 1.5, (m, 3))
    dv = rng.normal(0, 1.0, (m, 3))
    w = rng.normal(0, 0.3, 3)
    a_o = np.zeros((m, 3))
    share = np.where(rng.random(m) < 0.3, 1.0, 0.5)
    n_hat, rhs, h = rcbf_rows(dp, dv, w, a_o, share, 0.8, 0.5, 0.6)
    e1, e2 = rng.normal(0, 1, 3), rng.normal(0, 1, 3)
    clf = clf_terms(e1, e2, w, rng.normal(0, 0.5, 3), 0.5, 0.1, 1.0, 2.0)
    return dp, dv, w, share, n_hat, rhs, h, clf


def test_every_solution_satisfies_every_constraint():
    rng = np.random.default_rng(11)
    qp = SafetyQP(7, LO, HI, rho=10.0, clf_c=1.0)
    n_solved = n_relaxed = 0
    for _ in range(300):
        m = int(rng.integers(0, 8))
        dp, dv, w, share, n_hat, rhs, h, clf = _case(rng, m)
        r = qp.solve(clf.u_nom, clf, n_hat, rhs, h, brake=-w)
        assert np.all(np.isfinite(r.u))
        assert np.all(r.u >= LO - 1e-6) and np.all(r.u <= HI + 1e-6)
        if r.status in ("solved", "inactive"):
            n_solved += 1
            # independent check of the RCBF condition ḣ ≥ −γh³ with this agent's share
            base = 2 * np.einsum("ij,ij->i", dp, dv) + 2 * 0.8 * np.einsum("ij,ij->i", dv, dv)
            base += 0.6 * h**3
            lhs = 2 * 0.8 * (dp @ (r.u + w))
            assert np.all(lhs >= -share * base - 1e-4 * (1 + np.abs(base))), r.status
        else:
            n_relaxed += 1
            # infeasible with the box: every row violated by at most σ (min-violation)
            assert np.all(n_hat @ r.u + r.violation >= rhs - 1e-3)
    assert n_solved > 150


def test_inactive_equals_nominal_and_clf_decrease():
    rng = np.random.default_rng(2)
    qp = SafetyQP(7, LO, HI, rho=10.0, clf_c=1.0)
    e1, e2 = np.array([0.2, -0.1, 0.05]), np.array([0.0, 0.1, 0.0])
    clf = clf_terms(e1, e2, np.zeros(3), np.zeros(3), 0.5, 0.1, 1.0, 2.0)
    r = qp.solve(clf.u_nom, clf, np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(3))
    assert np.allclose(r.u, clf.u_nom)
    # nominal control gives V̇ = −2kpλ‖e1‖² − 2kd ks‖s‖² ≤ −cV (c = 1)
    vdot = clf.lfv + float(clf.lgv @ clf.u_nom)
    assert vdot <= -1.0 * clf.V + 1e-12
    del rng


def test_head_on_pair_brakes():
    qp = SafetyQP(7, LO, HI, rho=10.0, clf_c=1.0)
    dp = np.array([[0.0, 0.0, -1.0]])  # other agent 1 m above
    dv = np.array([[0.0, 0.0, 1.5]])  # closing at 1.5 m/s
    n_hat, rhs, h = rcbf_rows(dp, dv, np.zeros(3), np.zeros((1, 3)), np.array([0.5]),
                              0.8, 0.5, 0.6)
    assert barrier(dp, dv, 0.8, 0.5)[0] < 0
    clf = clf_terms(np.array([0, 0, -2.0]), np.zeros(3), np.zeros(3), np.zeros(3),
                    0.5, 0.1, 1.0, 2.0)  # nominal wants to go up
    r = qp.solve(clf.u_nom, clf, n_hat, rhs, h, brake=np.zeros(3))
    assert r.u[2] < 0  # brakes (pushes away) instead


def test_apf_repulsion_direction():
    f = apf_term(np.array([[0.0, 0.0, 0.8]]), np.array([-1.0]), 4.0, 1.0, 1.5)
    assert f[2] > 0 and abs(f[0]) < 1e-12
    assert np.allclose(apf_term(np.array([[2.0, 0, 0]]), np.array([0.0]), 4.0, 1.0, 1.5), 0)
