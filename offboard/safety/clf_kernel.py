"""Compiled CLF terms and nominal controller
(:func:`offboard.safety.rcbf.clf_rcbf.clf_terms_of_reference`; Departure 10,
docs/saturation.md §2).

One call gives V, L_fV, L_gV and u_nom, with or without the anti-windup box, using the
operations of the numpy formulation it replaced; dot products are summed left to right
(numpy's ``@`` went to BLAS), so the two agree to rounding
(``tests/unit/safety/test_clf_kernel.py``).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel

CLF_OUT = 8  # [V, L_fV, L_gV (3), u_nom (3)]


@kernel
def clf_into(
    e1: np.ndarray, e2: np.ndarray, w: np.ndarray, a_ref: np.ndarray, kp: float, kd: float,
    lam: float, ks: float, use_box: bool, lo: np.ndarray, hi: np.ndarray, brake_share: float,
    reserve: float, out: np.ndarray,
) -> None:
    """Writes ``out`` (CLF_OUT,) = [V (m²), L_fV (m²/s), L_gV (3, m·s), u_nom (3, m/s²)]
    (the caller's new array: none to box) for e1 (m), e2 (m/s), the
    disturbance estimate w and the reference acceleration a_ref (m/s²), gains k_p, k_d, λ,
    k_s. With ``use_box`` the nominal law has the anti-windup of docs/saturation.md §2 over
    the per-axis box [lo, hi] (m/s²), braking share β and feed-forward reserve."""
    s = np.empty(3)
    drift = np.empty(3)
    for k in range(3):
        s[k] = e2[k] + lam * e1[k]
        drift[k] = w[k] - a_ref[k] + lam * e2[k]
    e1e1 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
    out[0] = kp * e1e1 + kd * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
    out[1] = 2.0 * kp * (e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]) + 2.0 * kd * (
        s[0] * drift[0] + s[1] * drift[1] + s[2] * drift[2]
    )
    for k in range(3):
        out[2 + k] = 2.0 * kd * s[k]
    if not use_box:
        c_p = kp / kd
        for k in range(3):
            out[5 + k] = a_ref[k] - w[k] - lam * e2[k] - ks * s[k] - c_p * e1[k]
        return
    k_v = lam + ks
    c = (ks * lam + kp / kd) / k_v
    f_c = np.empty(3)
    b_hi = np.empty(3)
    b_lo = np.empty(3)
    v_r = np.empty(3)
    for k in range(3):
        m = reserve * 0.5 * (hi[k] - lo[k])
        f_c[k] = min(max(a_ref[k] - w[k], lo[k] + m), hi[k] - m)
        b_hi[k] = hi[k] - f_c[k]
        b_lo[k] = f_c[k] - lo[k]
        v_r[k] = -c * e1[k]
    n = math.sqrt(e1e1)
    if n > 1e-12:
        b_e = math.inf
        for k in range(3):
            d = e1[k] / n
            if abs(d) > 1e-12:
                room = b_hi[k] if d > 0.0 else b_lo[k]
                b_e = min(b_e, room / abs(d))
        scale = min(1.0, math.sqrt(2.0 * brake_share * b_e * n) / (c * n))
        for k in range(3):
            v_r[k] = v_r[k] * scale
    for k in range(3):
        fb = -k_v * (e2[k] - v_r[k])
        out[5 + k] = f_c[k] + min(max(fb, -b_lo[k]), b_hi[k])


@kernel
def nominal_into(
    z1: np.ndarray, z2: np.ndarray, xi: np.ndarray, tau_ff: float, w: np.ndarray, kp: float,
    kd: float, lam: float, ks: float, use_box: bool, lo: np.ndarray, hi: np.ndarray,
    brake_share: float, reserve: float, out: np.ndarray,
) -> None:
    """:func:`clf_into` (into ``out``) on the errors of the estimate (z1 (m), z2 (m/s))
    from the desired state ξ = [p*, v*, a*, j*] (12,), ``e1 = z1 − p*``, ``e2 = z2 − v*``,
    with the acceleration feed-forward taken ``tau_ff`` (s) ahead, ``a* + tau_ff j*``
    (m/s²)."""
    e1 = np.empty(3)
    e2 = np.empty(3)
    a_ff = np.empty(3)
    for k in range(3):
        e1[k] = z1[k] - xi[k]
        e2[k] = z2[k] - xi[3 + k]
        a_ff[k] = xi[6 + k] + tau_ff * xi[9 + k]
    clf_into(e1, e2, w, a_ff, kp, kd, lam, ks, use_box, lo, hi, brake_share, reserve, out)
