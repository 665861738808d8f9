"""The DCBF QP's exact solution with one active barrier row, alone or with the CLF row
(offboard.safety.dcbf.exact_kernel.pre_solve_kernel, called by DcbfQP.solve), against OSQP on
the same problems: where it applies, OSQP's answer is the same point (and slack) to its
tolerance; where it does not (two barrier rows, the input set active, a multiplier of
the wrong sign) OSQP runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from offboard.safety.dcbf.filter import input_set_of
from offboard.safety.dcbf.qp import DcbfQP
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from swarm_common.enums import QPSolver, QPStatus
from swarm_common.scenario.model import load_scenario

SC = load_scenario(Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def test_one_active_row_is_solved_exactly_and_matches_osqp() -> None:
    ctl = SC.controller
    uset = input_set_of(ctl, SC.vehicle)
    exact_qp = DcbfQP(8, uset, ctl.rho, ctl.clf_c)
    osqp_qp = DcbfQP(8, uset, ctl.rho, ctl.clf_c, solver=QPSolver.OSQP)
    rng = np.random.default_rng(14)
    exact = other = with_clf = 0
    for trial in range(400):
        u_nom = uset.project(rng.normal(0.0, 2.0, 3))
        m = int(rng.integers(1, 5))
        g = np.array([_unit(rng.normal(0.0, 1.0, 3)) for _ in range(m)])
        # rows satisfied by a margin, then one (sometimes two) pushed past u_nom
        rhs = g @ u_nom - rng.uniform(0.2, 3.0, m)
        for j in range(1 if trial % 4 else min(2, m)):
            rhs[j] = float(g[j] @ u_nom) + rng.uniform(0.01, 1.5)
        lgv = rng.normal(0.0, 0.05 if trial % 2 else 2.0, 3)  # the CLF row active or not
        clf = ClfTerms(V=1.0, lfv=0.0, lgv=lgv, u_nom=u_nom)
        brake = np.zeros(3)
        got = exact_qp.solve(u_nom, clf, g, rhs, 1.0, brake)
        if got.status_val == 0 and got.status is QPStatus.SOLVED:  # the exact path
            exact += 1
            u_c = uset.project(u_nom)
            clf_rhs = max(-clf.lfv - osqp_qp.c * clf.V, float(clf.lgv @ u_c))
            _, x = osqp_qp._solve_rows(u_nom, clf, clf_rhs, g, rhs, len(rhs))
            assert x is not None, trial
            assert np.allclose(got.u, x[0:3], atol=2e-4), (trial, got.u, x[0:3])
            assert abs(got.slack - x[3]) < 2e-4, (trial, got.slack, x[3])
            with_clf += got.slack > 1e-6
            assert (g @ got.u >= rhs).all(), trial
            assert uset.contains(got.u), trial
            viol = rhs - g @ u_nom
            assert int((viol > 0).sum()) == 1, trial
        else:
            other += 1
            assert got.status in (QPStatus.SOLVED, QPStatus.RELAXED), trial
    assert exact > 100 and other > 50 and with_clf > 30  # every path exercised
