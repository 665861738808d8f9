"""The dcbf pair barrier taller than it is wide (``controller.dcbf_vertical_scale`` κ,
docs/safety.md §4c): h = ‖SΔp‖² + 2τ (SΔv)ᵀ(SΔp) − D², S = diag(1, 1, 1/κ).

The compiled rows with κ are checked against a direct evaluation of the ellipsoidal h and ḣ
on the relative state predicted over the horizon (own lag model, the other at constant
acceleration), with the ē margins as the sup over a true-space error ‖e‖ ≤ ē and the
gradients by finite differences; κ = 1 is the sphere; a vertically stacked pair at 1.2·D is
outside the safe set with κ = 2 and inside with κ = 1; and a closed-loop stacked pair driven
together at the input limit keeps its ellipsoidal h ≥ 0 and κD apart."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gcs.report.verdict import pair_barrier
from offboard.inner_loop.attitude import InnerLoopModel, setpoint_from_accel
from offboard.safety.dcbf.filter import input_set_of
from offboard.safety.dcbf.kernel import dcbf_rows_kernel
from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.qp import DcbfQP
from offboard.safety.dcbf.step_kernel import (
    P_VERT_SCALE,
    GroundInput,
    OwnMotion,
    PairRows,
    RowsOut,
    RowsState,
    dcbf_filter_rows_into,
    dcbf_params,
)
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from swarm_common.barrier import barrier
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]

TAU_LAG = np.array([0.15, 0.15, 0.03])
DT = 0.02
LAG = LagCoefficients.of(TAU_LAG, 0.15 + DT)
TAU_S, D, G1, G3, EBAR = 0.8, 0.5, 0.3, 0.05, 2.0


State = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # Δp, Δv, a0, a_other


def _direct(st: State, u: np.ndarray, kappa: float,
            e: np.ndarray | None = None) -> tuple[float, float]:
    """(ĥ_T, ḣ_T) of the ellipsoidal barrier at the state predicted T ahead in true space
    (own acceleration from a0 toward u through the per-axis lag, the other at ao), with a
    constant relative-acceleration error e over [0, T] (m/s²), then scaled by S."""
    dp, dv, a0, ao = st
    t = LAG.T
    e = np.zeros(3) if e is None else e
    pv = dv + LAG.ia * a0 + LAG.cv * u - ao * t + e * t
    pp = dp + dv * t + LAG.iia * a0 + LAG.cp * u - 0.5 * ao * t * t + 0.5 * e * t * t
    pa = LAG.ea * a0 + LAG.ca * u - ao + e
    s = np.array([1.0, 1.0, 1.0 / kappa])
    sp, sv, sa = s * pp, s * pv, s * pa
    h = sp @ sp + 2.0 * TAU_S * (sv @ sp) - D * D
    hdot = 2.0 * (sp @ sv) + 2.0 * TAU_S * (sv @ sv + sp @ sa)
    return float(h), float(hdot)


def _grad(f: Callable[[np.ndarray], float], x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Central finite-difference gradient of the scalar f at x (3,)."""
    return np.array([(f(x + eps * b) - f(x - eps * b)) / (2 * eps) for b in np.eye(3)])


def _alpha(h: float) -> float:
    return G1 * h + G3 * h**3


@pytest.mark.parametrize("kappa", [1.0, 1.5, 2.0, 3.0])
def test_rows_match_a_direct_evaluation_of_the_ellipsoidal_barrier(kappa: float) -> None:
    """For random pairs, each row of the kernel is the linearisation at u_ref of the
    condition evaluated directly: C1 = ḣ_T − m_ḣ + α(ĥ_T − m_h), C2 = ĥ_T − m_h − (h0 − δ),
    margins m = sup_{‖e‖≤ē} (first-order change) = ‖∇_e‖ē in true space (held at u_ref),
    gradient in u by finite differences: unit g = ∇c/‖∇c‖ and gᵀu_ref − r = share·c/‖∇c‖."""
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(60):
        dp = rng.normal(0.0, 2.0, 3)
        dv = rng.normal(0.0, 1.5, 3)
        a0, u_ref, ao = rng.normal(0, 2, 3), rng.normal(0, 3, 3), rng.normal(0, 1, 3)
        share = float(rng.choice([0.5, 1.0]))
        g, r = dcbf_rows_kernel(dp[None], dv[None], a0, u_ref, ao[None], np.array([share]),
                                np.array([D]), LAG.table, LAG.sens3, LAG.T, TAU_S, G1, G3,
                                EBAR, kappa)
        st: State = (dp, dv, a0, ao)
        h_u, hd_u = _direct(st, u_ref, kappa)

        def h_t(u: np.ndarray, e: np.ndarray | None = None, st: State = st) -> float:
            return _direct(st, u, kappa, e)[0]

        def hd_t(u: np.ndarray, e: np.ndarray | None = None, st: State = st) -> float:
            return _direct(st, u, kappa, e)[1]

        m_h = float(np.linalg.norm(_grad(lambda e: h_t(u_ref, e), np.zeros(3)))) * EBAR  # noqa: B023
        m_hd = float(np.linalg.norm(_grad(lambda e: hd_t(u_ref, e), np.zeros(3)))) * EBAR  # noqa: B023
        h_lo = h_u - m_h
        sdp, sdv = dp * [1, 1, 1 / kappa], dv * [1, 1, 1 / kappa]
        h0 = float(sdp @ sdp + 2 * TAU_S * (sdv @ sdp) - D * D)
        drop = LAG.T * _alpha(h0)
        if h0 > 0:
            drop = min(drop, 0.5 * h0)
        c1 = hd_u - m_hd + _alpha(h_lo)
        c2 = h_lo - (h0 - drop)
        # the kernel's gradient: α's slope at h_lo, the margins not differentiated
        k_h = G1 + 3 * G3 * h_lo**2
        g1 = _grad(hd_t, u_ref) + k_h * _grad(h_t, u_ref)
        g2 = _grad(h_t, u_ref)
        for row, grad, c in ((0, g1, c1), (1, g2, c2)):
            n = np.linalg.norm(grad)
            if n < 1e-3:
                continue
            scale = 1.0 + abs(c) + n
            assert np.allclose(g[row], grad / n, atol=1e-5)
            assert g[row] @ u_ref - r[row] == pytest.approx(share * c / n, abs=1e-6 * scale)
            checked += 1
    assert checked > 100


def test_margin_with_kappa_is_tighter_than_the_unscaled_one() -> None:
    """‖S ∇‖ ē ≤ ‖∇‖ ē: a pair stacked vertically gets a smaller error margin (so a larger
    rhs slack) than the same scaled state fed to the sphere's rows would have: the error
    e enters as S e. Equal for a horizontal pair (S acts on z only)."""
    zero = np.zeros((1, 3))

    def rows(dp: list[float], kappa: float) -> np.ndarray:
        _, r = dcbf_rows_kernel(np.array([dp]), zero, np.zeros(3), np.zeros(3), zero,
                                np.ones(1), np.array([D]), LAG.table, LAG.sens3, LAG.T,
                                TAU_S, G1, G3, EBAR, kappa)
        return r

    # the vertical pair at 4 m with κ = 2 is the sphere's pair at 2 m, less margin
    assert np.all(rows([0.0, 0.0, 4.0], 2.0) < rows([0.0, 0.0, 2.0], 1.0))
    assert np.array_equal(rows([3.0, 1.0, 0.0], 2.0), rows([3.0, 1.0, 0.0], 1.0))


def test_kappa_one_is_the_sphere_bit_for_bit() -> None:
    """κ = 1 passed explicitly, through the step kernel's parameter, gives the same bits as
    the default (the rows of every scenario without the key)."""
    rng = np.random.default_rng(3)
    m = 5
    dp, dv = rng.normal(0, 2, (m, 3)), rng.normal(0, 1, (m, 3))
    args = (dp, dv, rng.normal(0, 2, 3), rng.normal(0, 2, 3), rng.normal(0, 1, (m, 3)),
            np.full(m, 0.5), np.full(m, D), LAG.table, LAG.sens3, LAG.T, TAU_S, G1, G3, EBAR)
    g_def, r_def = dcbf_rows_kernel(*args)
    g_one, r_one = dcbf_rows_kernel(*args, 1.0)
    assert np.array_equal(g_def, g_one) and np.array_equal(r_def, r_one)
    g_two, r_two = dcbf_rows_kernel(*args, 2.0)
    assert not np.array_equal(r_def, r_two)

    def step(kappa: float) -> tuple[np.ndarray, np.ndarray, float]:
        n = 6
        prm = dcbf_params(TAU_S, D, G1, G3, EBAR, 1.0, 3.0, DT, 0.5, 2.0, 1.0, LAG.T,
                          vertical_scale=kappa)
        assert prm[P_VERT_SCALE] == kappa
        state = RowsState(prm, LAG.table, LAG.sens3, np.zeros((n, 3)),
                          np.zeros(n, dtype=bool), np.zeros((n, 3)), np.zeros(n, dtype=bool))
        out = RowsOut(np.full((2 * m + 2, 3), np.nan), np.full(2 * m + 2, np.nan), np.zeros(3))
        rows = PairRows(dp, dv, np.arange(m, dtype=np.int64), np.zeros(m, dtype=bool),
                        np.zeros(m, dtype=bool), np.zeros(m), np.zeros((m, 3)))
        own = OwnMotion(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))
        k, h_min = dcbf_filter_rows_into(rows, own, GroundInput(False, 0.0, 0.0, 0.0), state,
                                         out)
        return out.g[:k].copy(), out.rhs[:k].copy(), h_min

    g1, r1, h1 = step(1.0)
    assert h1 == float(barrier(dp, dv, TAU_S, D).min())
    g2, r2, h2 = step(2.0)
    assert h2 == pytest.approx(float(barrier(dp, dv, TAU_S, D, 2.0).min()), abs=1e-12)
    assert not np.array_equal(r1, r2)


def test_stacked_pair_at_one_point_two_d_is_unsafe_only_with_kappa_two() -> None:
    """At rest, 1.2·D apart vertically: h < 0 with κ = 2 (inside the ellipsoid (D, D, 2D)),
    h > 0 with κ = 1; side by side at 1.2·D both are safe. The same in the rows' own
    barrier (h_min of the step kernel) and in the run metrics' pair_barrier."""
    zero = np.zeros((1, 3))
    up = np.array([[0.0, 0.0, 1.2 * D]])
    side = np.array([[1.2 * D, 0.0, 0.0]])
    assert barrier(up, zero, TAU_S, D, 2.0)[0] < 0.0 < barrier(up, zero, TAU_S, D, 1.0)[0]
    assert barrier(side, zero, TAU_S, D, 2.0)[0] > 0.0
    assert barrier(side, zero, TAU_S, D, 2.0)[0] == barrier(side, zero, TAU_S, D)[0]
    p = np.array([[[0.0, 0.0, 5.0], [0.0, 0.0, 5.0 + 1.2 * D]]])
    v = np.zeros_like(p)
    assert pair_barrier(p, v, TAU_S, D, 2.0)[0, 0] < 0.0 < pair_barrier(p, v, TAU_S, D)[0, 0]


def _fly_stacked(kappa: float) -> tuple[float, float, float, float]:
    """Two agents, one above the other, 50 Hz, the real lag model (cube8's vehicle), each
    nominal input at the input limit toward the other (the upper one dives, the lower one
    climbs), filtered with the rows of κ: (the true ellipsoidal h's minimum (m²), the
    smallest ‖SΔp‖ (m), the smallest vertical distance while horizontally closer than D
    (m), the smallest distance (m))."""
    sc = load_scenario(ROOT / "scenarios" / "cube8.toml")  # its vehicle and input set
    veh, ctl = sc.vehicle, sc.controller
    assert np.allclose(TAU_LAG, [veh.tau_rollpitch_s, veh.tau_rollpitch_s, veh.tau_thrust_s])
    fine = 4
    uset = input_set_of(ctl, veh)
    qps = [DcbfQP(2, uset, ctl.rho, ctl.clf_c) for _ in range(2)]
    inners = [InnerLoopModel(veh, DT / fine) for _ in range(2)]
    no_clf = ClfTerms(V=0.0, lfv=0.0, lgv=np.zeros(3), u_nom=np.zeros(3))
    p = [np.array([0.0, 0.0, 9.0]), np.array([0.02, 0.0, 4.0])]
    v = [np.array([0.0, 0.0, -1.5]), np.array([0.0, 0.0, 1.0])]
    a_real, u_prev = [np.zeros(3), np.zeros(3)], [np.zeros(3), np.zeros(3)]
    v_old = [x.copy() for x in v]
    s_k = np.array([1.0, 1.0, 1.0 / kappa])
    h_min, s_min, dz_min, d_min = np.inf, np.inf, np.inf, np.inf
    for _ in range(300):  # 6 s
        us = []
        for i in range(2):
            j = 1 - i
            dp, dv = (p[i] - p[j])[None], (v[i] - v[j])[None]
            a_j = ((v[j] - v_old[j]) / DT)[None]
            u_nom = uset.project(-dp[0] / np.linalg.norm(dp[0]) * 20.0)
            g, rhs = dcbf_rows_kernel(dp, dv, a_real[i], u_prev[i], a_j, np.array([0.5]),
                                      np.array([D]), LAG.table, LAG.sens3, LAG.T, TAU_S,
                                      G1, G3, EBAR, kappa)
            h = float(barrier(dp, dv, TAU_S, D, kappa)[0])
            us.append(qps[i].solve(u_nom, no_clf, g, rhs, h, -v[i]).u)
        v_old = [x.copy() for x in v]
        for i in range(2):
            sp = setpoint_from_accel(us[i], 0.0, veh)
            for a in inners[i].run(sp, fine):
                v[i] = v[i] + a * DT / fine
                p[i] = p[i] + v[i] * DT / fine
            a_real[i], u_prev[i] = a, us[i]
        dp, dv = (p[0] - p[1])[None], (v[0] - v[1])[None]
        h_min = min(h_min, float(barrier(dp, dv, TAU_S, D, kappa)[0]))
        s_min = min(s_min, float(np.linalg.norm(s_k * dp[0])))
        d_min = min(d_min, float(np.linalg.norm(dp[0])))
        if np.linalg.norm(dp[0, :2]) < D:
            dz_min = min(dz_min, float(abs(dp[0, 2])))
    return h_min, s_min, dz_min, d_min


def test_stacked_pair_driven_together_keeps_the_ellipsoid() -> None:
    """Closed loop (:func:`_fly_stacked`): with κ = 1 and κ = 2 the true barrier of the
    filter's own κ stays ≥ 0 and its ellipsoid is never entered (‖SΔp‖ ≥ D); with κ = 2
    the pair, while one is above the other, stays farther apart vertically than with
    κ = 1, and at least 2D."""
    one, two = _fly_stacked(1.0), _fly_stacked(2.0)
    for h_min, s_min, _, d_min in (one, two):
        assert h_min >= 0.0 and s_min >= D
        assert d_min < 4.0  # the nominal input did push them together
    assert two[2] >= 2.0 * D
    assert two[2] > one[2]
