"""The safety QPs' two solvers on shared test problems (offboard.safety.solvers.daqp_call beside
offboard.safety.solvers.osqp_call, ``[controller] qp_solver``): DAQP's answer meets every row, is no
worse than OSQP's and is the same point as OSQP's at a tight tolerance (1e-9, polished),
for the RCBF and the DCBF QP, with the hard rows feasible or relaxed and the CLF row and
the input set active or not; when DAQP reports no optimum, OSQP answers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from reference.clf_rows import clf_terms, rcbf_rows

from offboard.safety.dcbf.filter import input_set_of
from offboard.safety.dcbf.qp import DcbfQP
from offboard.safety.rcbf import clf_rcbf
from offboard.safety.rcbf.clf_rcbf import ClfTerms, SafetyQP, _ClfRowsQP
from swarm_common.enums import QPSolver, QPStatus
from swarm_common.scenario.model import load_scenario

SC = load_scenario(Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml")
LO = np.array([-3.2, -3.2, -8.0])
HI = np.array([3.2, 3.2, 8.0])
RHO, CLF_C = 10.0, 1.0
TIGHT = 1e-9  # OSQP's eps_abs = eps_rel for the reference answers


def _clf(rng: np.random.Generator, w: np.ndarray) -> ClfTerms:
    scale = rng.choice([0.05, 1.0, 3.0])  # CLF row slack, tight or active
    return clf_terms(rng.normal(0, scale, 3), rng.normal(0, scale, 3), w, np.zeros(3), 0.5,
                     0.1, 1.0, 2.0)


def _objective(qp: _ClfRowsQP, x: np.ndarray) -> float:
    """The QP's objective at x, from the problem the solver was given (q, H)."""
    return float(0.5 * x @ qp._h @ x + qp.q @ x)


def _rows_hold(qp: _ClfRowsQP, x: np.ndarray, k: int, tol: float) -> bool:
    """Every used row of the problem written last holds at x within ``tol``."""
    ax = qp._a @ x
    used = np.r_[0, 1 + np.arange(k), 1 + qp.m + np.arange(qp.nrow - 1 - qp.m)]
    return bool(np.all(ax[used] >= qp.l[used] - tol) and np.all(ax[used] <= qp.u[used] + tol))


def _compare(daqp_qp: _ClfRowsQP, osqp_qp: _ClfRowsQP, u_nom: np.ndarray, clf: ClfTerms,
             g: np.ndarray, rhs: np.ndarray, clf_rhs: float) -> tuple[np.ndarray, np.ndarray]:
    k = len(rhs)
    osqp_qp.solver.update_settings(max_iter=500_000)  # converge to TIGHT, however slowly
    sv_d, x_d = daqp_qp._solve_rows(u_nom, clf, clf_rhs, g, rhs, k)
    assert x_d is not None and sv_d == 1
    assert _rows_hold(daqp_qp, x_d, k, 1e-9)
    sv_o, x_o = osqp_qp._solve_rows(u_nom, clf, clf_rhs, g, rhs, k)
    assert x_o is not None
    assert _rows_hold(osqp_qp, x_o, k, 1e-6)
    assert _objective(daqp_qp, x_d) <= _objective(osqp_qp, x_o) + 1e-6
    return x_d, x_o


def test_rcbf_qp_daqp_matches_osqp() -> None:
    rng = np.random.default_rng(11)
    relaxed = 0
    for _ in range(300):
        m = int(rng.integers(1, 12))
        w = rng.normal(0, 0.3, 3)
        n_hat, rhs, _h = rcbf_rows(rng.normal(0, 1.2, (m, 3)), rng.normal(0, 1.5, (m, 3)), w,
                                   np.zeros((m, 3)), np.full(m, 0.5), 0.8, 0.5, 0.6)
        clf = _clf(rng, w)
        a = SafetyQP(m, LO, HI, RHO, CLF_C, solver=QPSolver.DAQP)
        b = SafetyQP(m, LO, HI, RHO, CLF_C, eps=TIGHT, solver=QPSolver.OSQP)
        u_c = np.clip(clf.u_nom, LO, HI)
        clf_rhs = max(-clf.lfv - CLF_C * clf.V, float(clf.lgv @ u_c))
        x_d, x_o = _compare(a, b, clf.u_nom, clf, n_hat, rhs, clf_rhs)
        assert np.allclose(x_d, x_o, atol=1e-6), (x_d, x_o)
        relaxed += x_d[4] > 1e-3
    assert relaxed > 10  # infeasible hard rows were among the problems


def test_dcbf_qp_daqp_matches_osqp() -> None:
    uset = input_set_of(SC.controller, SC.vehicle)
    rng = np.random.default_rng(12)
    outside = 0
    for _ in range(300):
        m = int(rng.integers(1, 10))
        u_nom = rng.normal(0, 4.0, 3)  # often outside the input polytope
        outside += not uset.contains(u_nom)
        g = rng.normal(0, 1, (m, 3))
        g /= np.linalg.norm(g, axis=1)[:, None]
        rhs = g @ u_nom + rng.normal(0.3, 1.5, m)
        clf = _clf(rng, np.zeros(3))
        clf = ClfTerms(clf.V, clf.lfv, clf.lgv, u_nom)
        a = DcbfQP(m, uset, RHO, CLF_C, solver=QPSolver.DAQP)
        b = DcbfQP(m, uset, RHO, CLF_C, eps=TIGHT, solver=QPSolver.OSQP)
        clf_rhs = max(-clf.lfv - CLF_C * clf.V, float(clf.lgv @ uset.project(u_nom)))
        x_d, x_o = _compare(a, b, u_nom, clf, g, rhs, clf_rhs)
        assert uset.contains(x_d[0:3], tol=1e-9)
        assert np.allclose(x_d, x_o, atol=1e-6), (x_d, x_o)
    assert outside > 50


def test_no_daqp_optimum_falls_back_to_osqp(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(13)
    w = rng.normal(0, 0.3, 3)
    n_hat, rhs, h = rcbf_rows(rng.normal(0, 0.8, (6, 3)), rng.normal(0, 2.0, (6, 3)), w,
                              np.zeros((6, 3)), np.full(6, 0.5), 0.8, 0.5, 0.6)
    clf = _clf(rng, w)
    want = SafetyQP(6, LO, HI, RHO, CLF_C, solver=QPSolver.OSQP).solve(
        clf.u_nom, clf, n_hat, rhs, h, brake=-w)
    assert want.status in (QPStatus.SOLVED, QPStatus.RELAXED)
    calls: list[int] = []

    def no_optimum(*args: object, **kwargs: object) -> None:
        calls.append(1)
        return None

    monkeypatch.setattr(clf_rcbf, "daqp_solve", no_optimum)
    got = SafetyQP(6, LO, HI, RHO, CLF_C, solver=QPSolver.DAQP).solve(
        clf.u_nom, clf, n_hat, rhs, h, brake=-w)
    assert calls  # DAQP was asked first
    assert got.status == want.status and not got.fallback
    assert np.array_equal(got.u, want.u)  # then OSQP's answer, the same problem cold


def test_solver_choice_is_validated_on_load(tmp_path: Path) -> None:
    src = (Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml").read_text()
    assert 'qp_solver' not in src  # optional: the default applies
    assert SC.controller.qp_solver is QPSolver.DAQP
    bad = tmp_path / "bad.toml"
    bad.write_text(src.replace("[controller]\n", '[controller]\nqp_solver = "cvxopt"\n', 1))
    with pytest.raises(ValueError, match="qp_solver"):
        load_scenario(bad)
    good = tmp_path / "osqp.toml"
    good.write_text(src.replace("[controller]\n", '[controller]\nqp_solver = "osqp"\n', 1))
    assert load_scenario(good).controller.qp_solver is QPSolver.OSQP


def test_daqp_on_hostile_data_answers_finite_or_not_at_all() -> None:
    """Extreme magnitudes (1e-300 … 1e300), zero and duplicate rows, infinite bounds and
    infeasible problems: the adapter returns a finite x or None (then OSQP runs), never a
    non-finite x, and the extension does not crash."""
    from offboard.safety.solvers.daqp_call import daqp_solve

    rng = np.random.default_rng(17)
    h = np.diag([1.0, 1.0, 1.0, 2.0 * RHO, 200.0])
    answered = refused = 0
    for trial in range(3000):
        m = int(rng.integers(1, 40))
        a = rng.normal(0, 1, (m, 5))
        if trial % 3 == 0:
            a *= 10.0 ** rng.uniform(-300, 300, (m, 5)) * rng.choice([-1, 0, 1], (m, 5))
        if trial % 5 == 0 and m > 2:
            a[1] = a[0]
        if trial % 7 == 0:
            a[0] = 0.0
        lo = rng.normal(0, 1, m) * 10.0 ** rng.uniform(-5, 300 if trial % 4 == 0 else 3, m)
        hi = lo + np.abs(rng.normal(0, 1, m)) * 10.0 ** rng.uniform(-5, 3, m)
        lo[rng.random(m) < 0.3] = -np.inf
        hi[rng.random(m) < 0.3] = np.inf
        q = rng.normal(0, 1, 5) * 10.0 ** rng.uniform(-3, 300 if trial % 6 == 0 else 3, 5)
        x = daqp_solve(h, q, np.ascontiguousarray(a), lo, hi)
        if x is None:
            refused += 1
        else:
            answered += 1
            assert x.shape == (5,) and np.isfinite(x).all()
    assert answered > 100 and refused > 100


def _dcbf_problems(
    rng: np.random.Generator, n: int
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    out = []
    for _ in range(n):
        m = int(rng.integers(1, 9))
        u_nom = rng.normal(0, 4.0, 3)
        g = rng.normal(0, 1, (m, 3))
        g /= np.linalg.norm(g, axis=1)[:, None]
        out.append((u_nom, g, g @ u_nom + rng.normal(0.3, 1.5, m)))
    return out


def test_osqp_set_up_on_first_use_is_the_solver_set_up_with_the_problem() -> None:
    """OSQP is set up on first use (offboard.safety.rcbf.clf_rcbf._ClfRowsQP.solver) from the data
    the
    problem was built with, not from the rows written since: a solver first used after
    rows were written answers every later problem with the same bits as one set up when
    the problem was built."""
    uset = input_set_of(SC.controller, SC.vehicle)
    rng = np.random.default_rng(21)
    early = DcbfQP(8, uset, RHO, CLF_C, solver=QPSolver.OSQP)
    late = DcbfQP(8, uset, RHO, CLF_C, solver=QPSolver.OSQP)
    assert early.solver is early.solver  # set up now, once
    assert late._osqp is None
    for u_nom, g, rhs in _dcbf_problems(rng, 60):
        clf = _clf(rng, np.zeros(3))
        clf = ClfTerms(clf.V, clf.lfv, clf.lgv, u_nom)
        got = [qp.solve(u_nom, clf, g, rhs, 0.0, np.zeros(3)) for qp in (early, late)]
        assert np.array_equal(got[0].u, got[1].u) and got[0].status == got[1].status


def test_daqp_alone_never_sets_up_osqp_and_a_grown_problem_gets_its_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    uset = input_set_of(SC.controller, SC.vehicle)
    rng = np.random.default_rng(22)
    qp = DcbfQP(2, uset, RHO, CLF_C, limit=16, solver=QPSolver.DAQP)
    for u_nom, g, rhs in _dcbf_problems(rng, 40):
        clf = _clf(rng, np.zeros(3))
        qp.solve(u_nom, ClfTerms(clf.V, clf.lfv, clf.lgv, u_nom), g, rhs, 0.0, np.zeros(3))
    assert qp.m > 2  # grew on demand
    assert qp._osqp is None  # DAQP answered every solve
    monkeypatch.setattr(clf_rcbf, "daqp_solve", lambda *a, **k: None)  # no DAQP optimum
    u_nom, g, rhs = _dcbf_problems(rng, 1)[0]
    sv, x = qp._solve_rows(u_nom, _clf(rng, np.zeros(3)), 0.0, g, rhs, len(rhs))
    assert qp._osqp is not None and x is not None  # OSQP, set up for the grown problem
    assert _rows_hold(qp, x, len(rhs), 1e-3)
