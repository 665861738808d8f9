"""Compiled barrier rows of the sampled-data CBF (``Method.DCBF``; docs/safety.md §4).

:func:`dcbf_rows_kernel` makes the rows pair by pair in one compiled loop: the prediction
T ahead, the sensitivities of ``ḣ_T`` and ``ĥ_T`` to a constant acceleration error and to
the command, and the two rows (C1), (C2) per pair. The operations and their order are
those of the numpy formulation it replaced (kept in ``tests/reference/dcbf_rows.py``),
but for two: cubes are products (numpy's ``**3`` is its own vectorised power) and dot
products are summed left to right (numpy's ``einsum`` and ``@`` sum in their own orders).
The rows agree with that formulation to rounding (``tests/unit/safety/test_dcbf_kernel.py``,
random pairs), and every process that runs the kernel computes the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel


@kernel
def _dot3(a: np.ndarray, b: np.ndarray) -> float:
    """a·b of two 3-vectors, summed left to right (m², m²/s, …)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel
def dcbf_rows_kernel(
    dp: np.ndarray, dv: np.ndarray, a0: np.ndarray, u_ref: np.ndarray, a_other: np.ndarray,
    share: np.ndarray, d_safe: np.ndarray, lag: np.ndarray, sens: np.ndarray,
    horizon: float, tau_s: float, gamma1: float, gamma3: float, accel_err: float,
    vertical_scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``gᵀu ≥ r`` (g (2M,3) unit rows, r (2M,) m/s²): first the M (C1) rows, then
    the M (C2) rows, pair by pair in the order of ``dp``.

    The relative state is predicted T ahead: the own acceleration from a0 toward u through
    the lag, the other agent at constant acceleration a_other; h and ḣ (§2.3) there, ĥ_T
    and ḣ_T. With α(h) = γ1 h + γ3 h³ and h0 the barrier now, two conditions per pair:

    * (C1) ``f(u) = ḣ_T − ‖∂ḣ_T/∂a‖ ē + α(ĥ_T − ‖∂ĥ_T/∂a‖ ē) ≥ 0`` (the CBF condition at
      x̂_T; α increasing, so the error enters α exactly, not through α'(ĥ_T), which for
      the cubic term made every pair within ≈ 2.9 m repel: docs/safety.md §4);
    * (C2) ``ĥ_T − ‖∂ĥ_T/∂a‖ ē ≥ h0 − min(T α(h0), h0/2)`` (h0 > 0; ``h0 − T α(h0)``
      for h0 ≤ 0, which demands growth): h does not dip over the horizon.

    Each linearised at ``u_ref``: ``gᵀ(u − u_ref) ≥ −share·c(u_ref)``. ``ē`` (m/s²) bounds
    the error of the assumed relative acceleration over [0, T] (model, estimates). The
    sensitivities are those of ``sens``: [0] a constant relative-acceleration error e
    over [0, T] (moves Δv̂ by eT, Δp̂ by eT²/2), [1] the command u through the lag.

    dp, dv (M,3) relative position (m) and velocity (m/s) now; a0, u_ref (3,) realised
    acceleration and linearisation command (m/s²); a_other (M,3) the other agent's assumed
    acceleration (m/s²); share (M,); d_safe (M,) safety distance (m); lag (6,3) the rows
    ca, cv, cp, ea, ia, iia of :class:`offboard.safety.dcbf.model.LagCoefficients`; sens (3,2,3) its
    sensitivities (p|v|a, error|command, axis); horizon T (s); tau_s look-ahead τ (s);
    gamma1 (1/s), gamma3 (1/(m⁴ s)) of α(h) = γ1 h + γ3 h³; accel_err ē (m/s²).

    ``vertical_scale`` κ ≥ 1 (docs/safety.md §4c): the barrier of the scaled relative state
    S Δp, S Δv, S = diag(1, 1, 1/κ) (safe set outside the ellipsoid (D, D, κD)). Every
    term of the prediction is linear in Δp, Δv, a0, u, a_other and the lag is per axis, so
    the rows of S x are those of the inputs scaled by S, with the command entering as S u
    (the command's gradient is S times the scaled one) and the margins ``‖S ∂/∂a‖ ē`` (the
    error e, ‖e‖ ≤ ē, enters as S e). κ = 1 multiplies by 1.0, which changes no bit.
    """
    m = dp.shape[0]
    t = horizon
    ca, cv, cp, ea, ia, iia = lag[0], lag[1], lag[2], lag[3], lag[4], lag[5]
    sc = np.ones(3)
    sc[2] = 1.0 / vertical_scale
    a0s = a0 * sc
    us = u_ref * sc
    own_v = ia * a0s + cv * us
    own_p = iia * a0s + cp * us
    own_a = ea * a0s + ca * us
    g = np.empty((2 * m, 3))
    rhs = np.empty(2 * m)
    pv = np.empty(3)
    pp = np.empty(3)
    pa = np.empty(3)
    sdp = np.empty(3)
    sdv = np.empty(3)
    e_hd = np.empty(3)
    e_hh = np.empty(3)
    hd = np.empty((2, 3))
    hh = np.empty((2, 3))
    two_tau = 2.0 * tau_s
    for i in range(m):
        for k in range(3):
            sdp[k] = dp[i, k] * sc[k]
            sdv[k] = dv[i, k] * sc[k]
            ao = a_other[i, k] * sc[k]
            pv[k] = sdv[k] + own_v[k] - ao * t
            pp[k] = sdp[k] + sdv[k] * t + own_p[k] - 0.5 * ao * t * t
            pa[k] = own_a[k] - ao
        dd = d_safe[i] ** 2
        vp = _dot3(pv, pp)
        h = _dot3(pp, pp) + two_tau * vp - dd
        hdot = 2.0 * vp + two_tau * (_dot3(pv, pv) + _dot3(pp, pa))
        # [0] acceleration error, [1] command (offboard.safety.dcbf.model._grads)
        for s in range(2):
            for k in range(3):
                sp, sv, sa = sens[0, s, k], sens[1, s, k], sens[2, s, k]
                hd[s, k] = 2.0 * (sp * pv[k] + sv * pp[k]) + two_tau * (
                    2.0 * sv * pv[k] + sp * pa[k] + sa * pp[k]
                )
                hh[s, k] = 2.0 * sp * pp[k] + two_tau * (sv * pp[k] + sp * pv[k])
        for k in range(3):  # the error enters as S e
            e_hd[k] = hd[0, k] * sc[k]
            e_hh[k] = hh[0, k] * sc[k]
        m_h = math.sqrt(_dot3(e_hh, e_hh)) * accel_err
        h_lo = h - m_h
        k_h = gamma1 + 3.0 * gamma3 * h_lo**2
        c1 = hdot - math.sqrt(_dot3(e_hd, e_hd)) * accel_err + gamma1 * h_lo
        c1 = c1 + gamma3 * (h_lo * h_lo * h_lo)
        h0 = _dot3(sdp, sdp) + two_tau * _dot3(sdv, sdp) - dd
        drop = t * (gamma1 * h0 + gamma3 * (h0 * h0 * h0))
        if h0 > 0.0:
            drop = min(drop, 0.5 * h0)
        c2 = h - m_h - (h0 - drop)
        for k in range(3):  # the command enters as S u
            g[i, k] = (hd[1, k] + k_h * hh[1, k]) * sc[k]
            g[m + i, k] = hh[1, k] * sc[k]
        for r, c in ((i, c1), (m + i, c2)):
            nrm = max(math.sqrt(_dot3(g[r], g[r])), 1e-9)
            rhs[r] = (_dot3(g[r], u_ref) - share[i] * c) / nrm
            for k in range(3):
                g[r, k] = g[r, k] / nrm
    return g, rhs


@kernel
def other_term_kernel(
    pairs: np.ndarray, predicted: np.ndarray, dv: np.ndarray, other_acc: np.ndarray,
    w_safe: np.ndarray, a_mean: np.ndarray, dt: float, smooth: float,
    prev_dv: np.ndarray, prev_ok: np.ndarray, rel_acc: np.ndarray, rel_ok: np.ndarray,
) -> np.ndarray:
    """(M,3) ``a_j − w_i`` (m/s²) of :meth:`offboard.safety.dcbf.filter.DcbfFilter._other_term`.

    pairs (M,) scenario index j per row; predicted (M,) rows from prediction (no sensed
    history); dv (M,3) Δv = v_i − v_j now (m/s); other_acc (M,3) the other's broadcast
    acceleration estimate (m/s²); w_safe (3,) own saturated disturbance; a_mean (3,) own
    mean realised control over the last period (m/s²); dt (s); smooth the low-pass weight
    of the previous relative acceleration. The per-index state prev_dv (N,3), prev_ok
    (N,), rel_acc (N,3), rel_ok (N,) is read and updated in place.
    """
    m = pairs.shape[0]
    out = np.empty((m, 3))
    for r in range(m):
        for k in range(3):
            out[r, k] = other_acc[r, k] - w_safe[k]
    keep = 1.0 - smooth
    da = np.empty(3)
    for r in range(m):
        if predicted[r]:
            continue
        j = pairs[r]
        if not prev_ok[j]:
            rel_ok[j] = False  # a pair seen again after a gap starts afresh
            continue
        for k in range(3):
            da[k] = (dv[r, k] - prev_dv[j, k]) / dt
        if rel_ok[j]:
            for k in range(3):
                da[k] = smooth * rel_acc[j, k] + keep * da[k]
        for k in range(3):
            rel_acc[j, k] = da[k]
            out[r, k] = a_mean[k] - da[k]
        rel_ok[j] = True
    prev_ok[:] = False
    for r in range(m):
        if predicted[r]:
            continue
        j = pairs[r]
        prev_ok[j] = True
        for k in range(3):
            prev_dv[j, k] = dv[r, k]
    return out


@kernel
def rows_hold_kernel(
    a_u: np.ndarray, lo_u: np.ndarray, hi_u: np.ndarray, g: np.ndarray, rhs: np.ndarray,
    k: int, u: np.ndarray,
) -> bool:
    """True if ``u`` (3,) is inside the input set ``lo_u ≤ A_U u ≤ hi_u`` and satisfies the
    first k barrier rows ``gᵀu ≥ r``: the QP's exact shortcut (its solution is then u)."""
    for r in range(a_u.shape[0]):
        y = a_u[r, 0] * u[0] + a_u[r, 1] * u[1] + a_u[r, 2] * u[2]
        if not (y <= hi_u[r] and y >= lo_u[r]):
            return False
    for r in range(k):
        if not (g[r, 0] * u[0] + g[r, 1] * u[1] + g[r, 2] * u[2] >= rhs[r]):
            return False
    return True


@kernel
def saturate_into(x: np.ndarray, bound: float, out: np.ndarray) -> None:
    """``out`` = x (3,) scaled down to Euclidean norm ``bound`` if longer, else x: the
    bits of :func:`offboard.safety.base.saturate_norm` (the squares summed in order,
    ``(x0² + x1²) + x2²``; a nan norm leaves x as it is)."""
    n = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if n > bound:
        s = bound / n
        for k in range(3):
            out[k] = x[k] * s
    else:
        for k in range(3):
            out[k] = x[k]


@kernel
def project_into(out: np.ndarray, proj: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray) -> None:
    """:meth:`offboard.safety.dcbf.model.InputSet.project` of a finite u (3,) (m/s²), in place in
    ``out`` (u on entry; no array to box): with ``proj`` = (uz_lo, uz_hi, uh_lo, uh_hi,
    cone_c, g, shrink) (:attr:`offboard.safety.dcbf.model.InputSet.projection`), u_z clipped to
    [uz_lo, uz_hi], u_x, u_y to [uh_lo, uh_hi], then u_h scaled inward onto the tilt cone
    ``cos_aᵀu_h ≤ (g + u_z)·cone_c − shrink``. The same operations in the same order as
    the numpy method (Python's min/max semantics), so the same bits."""
    uz_lo, uz_hi, uh_lo, uh_hi, cone_c, g, shrink = (
        proj[0], proj[1], proj[2], proj[3], proj[4], proj[5], proj[6]
    )
    z = out[2]
    z = uz_lo if uz_lo > z else z
    out[2] = uz_hi if uz_hi < z else z
    for a in range(2):
        x = out[a]
        x = uh_lo if uh_lo > x else x
        out[a] = uh_hi if uh_hi < x else x
    r = (g + out[2]) * cone_c - shrink
    worst = cos_a[0] * out[0] + sin_a[0] * out[1]
    for i in range(1, cos_a.shape[0]):
        side = cos_a[i] * out[0] + sin_a[i] * out[1]
        if side > worst:
            worst = side
    if worst > r:
        scale = (r if r > 0.0 else 0.0) / worst
        out[0] *= scale
        out[1] *= scale


@kernel
def ground_rows_kernel(
    z: float, vz: float, a0z: float, wz: float, floor: float, t: float, iia: float,
    ia: float, ea: float, cp: float, cv: float, ca: float, tau_s: float, gamma1: float,
    accel_err: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The two ground-barrier rows ``gᵀu ≥ r`` (g (2,3) = e_z, r (2,) m/s²) keeping an
    airborne agent at altitude z (m), vertical velocity vz (m/s) above ``floor`` (m),
    from the z-axis lag coefficients over T = ``t`` (s); the arithmetic and its order
    are those of the numpy formulation (``tests/reference/dcbf_rows.py``).

    The ground barrier ``h_g = z − floor + τ v_z`` (m; τ = ``tau_s``, the same look-ahead
    as the pair barrier) is linear in the state, so its prediction T ahead is linear in
    u_z and the rows are exact (no linearisation): with the own disturbance ``wz``
    (m/s²) held and the error bound ē on the vertical acceleration over [0, T]::

        ẑ_T = z + v_z T + iia a0 + cp u_z + wz T²/2,  v̂_T = v_z + ia a0 + cv u_z + wz T
        â_T = E a0 + ca u_z + wz
        (C1) v̂_T + τ â_T − ē(T + τ) + γ1 (ĥ_gT − ē(T²/2 + τT)) ≥ 0
        (C2) ĥ_gT − ē(T²/2 + τT) ≥ h_g0 − min(T γ1 h_g0, h_g0/2)    (h_g0 − Tγ1h_g0 if ≤ 0)
    """
    z_free = z + vz * t + iia * a0z + 0.5 * wz * t * t
    v_free = vz + ia * a0z + wz * t
    a_free = ea * a0z + wz
    h_free = z_free - floor + tau_s * v_free
    m_h = accel_err * (0.5 * t * t + tau_s * t)
    h0 = z - floor + tau_s * vz
    drop = t * gamma1 * h0
    if h0 > 0.0:
        half = 0.5 * h0
        drop = half if half < drop else drop
    k1 = cv + tau_s * ca + gamma1 * (cp + tau_s * cv)
    r1 = -(v_free + tau_s * a_free - accel_err * (t + tau_s) + gamma1 * (h_free - m_h)) / k1
    k2 = cp + tau_s * cv
    r2 = (h0 - drop - (h_free - m_h)) / k2
    g = np.zeros((2, 3))
    g[0, 2] = 1.0
    g[1, 2] = 1.0
    r = np.empty(2)
    r[0] = r1
    r[1] = r2
    return g, r
