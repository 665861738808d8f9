"""The compiled CLF terms and nominal controller (offboard.safety.clf_kernel through
clf_terms of tests/reference/clf_rows.py) against the numpy formulation they replaced, kept
here as the oracle: equal to rounding (the kernel sums dot products left to right, numpy used BLAS).
Also checked numerically: V̇ = L_fV + L_gV u along the error dynamics, by finite
differences."""

from __future__ import annotations

import math

import numpy as np
from reference.clf_rows import clf_terms
from reference.close import assert_close

from offboard.safety.rcbf.clf_rcbf import AW_BRAKE_SHARE, AW_RESERVE


def anti_windup_numpy(e1, e2, ff, k_v, c, box, brake_share=AW_BRAKE_SHARE,
                      reserve=AW_RESERVE):
    lo, hi = box
    m = reserve * 0.5 * (hi - lo)
    f_c = np.minimum(np.maximum(ff, lo + m), hi - m)
    b_hi, b_lo = hi - f_c, f_c - lo
    v_r = -c * e1
    n = math.sqrt(float(e1 @ e1))
    if n > 1e-12:
        d = e1 / n
        room = np.where(d > 0.0, b_hi, b_lo)
        nz = np.abs(d) > 1e-12
        b_e = float((room[nz] / np.abs(d[nz])).min())
        v_r *= min(1.0, math.sqrt(2.0 * brake_share * b_e * n) / (c * n))
    fb = -k_v * (e2 - v_r)
    return f_c + np.minimum(np.maximum(fb, -b_lo), b_hi)


def clf_numpy(e1, e2, w, a_ref, kp, kd, lam, ks, box=None):
    s = e2 + lam * e1
    v = kp * float(e1 @ e1) + kd * float(s @ s)
    drift = w - a_ref + lam * e2
    lfv = 2.0 * kp * float(e1 @ e2) + 2.0 * kd * float(s @ drift)
    lgv = 2.0 * kd * s
    if box is None:
        u_nom = a_ref - w - lam * e2 - ks * s - (kp / kd) * e1
    else:
        k_v = lam + ks
        u_nom = anti_windup_numpy(e1, e2, a_ref - w, k_v, (ks * lam + kp / kd) / k_v, box)
    return v, lfv, lgv, u_nom


def test_clf_terms_equal_numpy_formulation() -> None:
    rng = np.random.default_rng(12)
    box = (np.array([-8.0, -8.0, -6.0]), np.array([8.0, 8.0, 6.0]))
    for trial in range(3000):
        scale = 10.0 ** rng.uniform(-4, 1)  # from converged to far off
        e1, e2 = rng.normal(0, scale, 3), rng.normal(0, scale, 3)
        w, a_ref = rng.normal(0, 1, 3), rng.normal(0, 4, 3)  # a_ref may leave the box
        gains = (0.5, 0.1, 1.0, 2.0) if trial % 2 else tuple(rng.uniform(0.1, 3.0, 4))
        b = box if trial % 3 else None
        got = clf_terms(e1, e2, w, a_ref, *gains, box=b)
        v, lfv, lgv, u_nom = clf_numpy(e1, e2, w, a_ref, *gains, box=b)
        assert math.isclose(got.V, v, rel_tol=1e-12, abs_tol=1e-15), trial
        assert math.isclose(got.lfv, lfv, rel_tol=1e-11, abs_tol=1e-12), trial
        assert np.allclose(got.lgv, lgv, rtol=1e-12, atol=1e-15), trial
        assert np.allclose(got.u_nom, u_nom, rtol=1e-12, atol=1e-12), trial
        if b is not None:
            assert (got.u_nom >= box[0] - 1e-12).all() and (got.u_nom <= box[1] + 1e-12).all()
    # e1 = 0 exactly: no reference-velocity limit, no division by zero
    got = clf_terms(np.zeros(3), np.ones(3), np.zeros(3), np.zeros(3), 0.5, 0.1, 1.0, 2.0,
                    box=box)
    assert np.isfinite(got.u_nom).all()


def test_vdot_is_lfv_plus_lgv_u_along_the_error_dynamics() -> None:
    """ė1 = e2, ė2 = u + w − a_ref (a_ref constant): V(t+h) − V(t−h) over 2h matches
    L_fV + L_gV u (the CLF of Departure 10)."""
    rng = np.random.default_rng(13)
    kp, kd, lam, ks = 0.5, 0.1, 1.0, 2.0
    for _ in range(50):
        e1, e2, w, a_ref, u = (rng.normal(0, 1, 3) for _ in range(5))
        acc = u + w - a_ref
        h = 1e-6
        v_p, v_m = (clf_terms(e1 + e2 * t + 0.5 * acc * t * t, e2 + acc * t, w, a_ref,
                              kp, kd, lam, ks).V for t in (h, -h))
        fd = (v_p - v_m) / (2 * h)
        c = clf_terms(e1, e2, w, a_ref, kp, kd, lam, ks)
        assert math.isclose(fd, c.lfv + float(c.lgv @ u), rel_tol=1e-6, abs_tol=1e-6)


def test_terms_of_a_reference_are_the_terms_of_its_errors() -> None:
    """clf_terms_of_reference (errors and feed-forward formed in the kernel) against
    clf_terms of the errors and feed-forward formed in numpy, with and without the box:
    within rounding (tests/reference/close.py; the subtractions are made in two places)."""
    from offboard.safety.rcbf.clf_rcbf import clf_terms_of_reference

    rng = np.random.default_rng(12)
    lo, hi = np.array([-4.0, -4.0, -8.0]), np.array([4.0, 4.0, 6.0])
    for trial in range(500):
        z1, z2, w = rng.normal(0, 3, 3), rng.normal(0, 2, 3), rng.normal(0, 1, 3)
        xi = rng.normal(0, 2, 12)
        tau = float(rng.uniform(0.0, 0.3))
        gains = tuple(float(x) for x in rng.uniform(0.5, 5.0, 4))
        box = (lo, hi) if trial % 2 else None
        got = clf_terms_of_reference(z1, z2, xi, tau, w, *gains, box=box)
        want = clf_terms(z1 - xi[0:3], z2 - xi[3:6], w, xi[6:9] + tau * xi[9:12], *gains,
                         box=box)
        assert_close([got.V, got.lfv], [want.V, want.lfv], trial)
        assert_close(got.lgv, want.lgv, trial)
        assert_close(got.u_nom, want.u_nom, trial)
