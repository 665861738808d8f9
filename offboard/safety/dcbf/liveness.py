"""The closest spacing at which two dcbf agents can hover side by side (docs/safety.md,
"Dense formations: liveness"). Pure.

The pair rows of :func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel` carry two margins for
the relative-acceleration error bound ē (A3): ``‖∂ḣ_T/∂a‖ē`` in (C1) and ``‖∂ĥ_T/∂a‖ē``
in (C1), (C2). For a pair at rest at distance d they grow like d (≈ 2(T + τ_s)dē and
≈ 2(T²/2 + τ_s T)dē), while the class-K function α(h) that pays for them grows like
γ1 h. Below a distance d* the zero command breaks a row: the filter then demands that the
pair accelerate apart, and no formation whose neighbours are closer than d* can be held
at rest, whatever the nominal controller does (cube8's gains: d* ≈ 2.75 m, so dense
cubes of edge 1.5–2.5 m never form while a 3 m cube does). :func:`rest_spacing_m`
computes d* from the rows themselves, horizontally and vertically (the vertical lag τ_F
differs from the horizontal τ_rp), for a load-time liveness check.
"""

from __future__ import annotations

import numpy as np

from offboard.safety.dcbf.kernel import dcbf_rows_kernel
from offboard.safety.dcbf.model import LagCoefficients


def rest_rows_hold(
    d: float, axis: int, lag: LagCoefficients, tau_s: float, d_safe: float, gamma1: float,
    gamma3: float, accel_err: float, vertical_scale: float = 1.0,
) -> bool:
    """True if two agents at rest (zero relative velocity and acceleration, realised
    control 0, i.e. hovering) ``d`` metres apart along ``axis`` (0, 1: horizontal, 2:
    vertical) keep both pair rows (C1), (C2) with the zero command: ``r ≤ 0`` in
    ``gᵀu ≥ r`` at u = 0. Arguments as :func:`dcbf_rows_kernel`'s (s, m, 1/s,
    1/(m⁴ s), m/s², the barrier's vertical scale κ)."""
    dp = np.zeros((1, 3))
    dp[0, axis] = d
    _, rhs = dcbf_rows_kernel(
        dp, np.zeros((1, 3)), np.zeros(3), np.zeros(3), np.zeros((1, 3)), np.ones(1),
        np.array([d_safe]), lag.table, lag.sens3, lag.T, tau_s, gamma1, gamma3, accel_err,
        vertical_scale,
    )
    return bool(np.all(rhs <= 0.0))


def rest_spacing_m(
    tau_rp: float, tau_f: float, dt: float, tau_s: float, d_safe: float, gamma1: float,
    gamma3: float, accel_err: float, tol: float = 1e-3, d_max: float = 1e3,
    vertical_scale: float = 1.0, axes: tuple[int, ...] = (0, 2),
) -> float:
    """d* (m): the smallest distance from which on two hovering agents keep both pair rows
    with the zero command, the larger of the horizontal and the vertical one, to within
    ``tol`` (m). Lags τ_rp, τ_F (s), control period dt (s) (horizon T = τ_rp + dt, as
    :meth:`offboard.safety.dcbf.filter.DcbfFilter.configure`); the barrier's τ_s (s) and
    D (m); α's γ1 (1/s), γ3 (1/(m⁴ s)); ē (m/s²). ``inf`` if no distance up to ``d_max``
    holds (γ1 = γ3 = 0 with ē > 0). ``vertical_scale`` κ: the barrier's (docs/safety.md
    §4c; the vertical d* grows about κ-fold); ``axes``: those to take the larger over
    (0: horizontal, 2: vertical).

    The rows hold from d* on: their margins grow linearly in d, α(h) at least
    quadratically, so the set of distances that hold is an interval [d*, ∞) (checked
    by dense sampling in the tests); d* is found by doubling, then bisection."""
    lag = LagCoefficients.of(np.array([tau_rp, tau_rp, tau_f]), tau_rp + dt)
    worst = 0.0
    for axis in axes:
        def ok(d: float, axis: int = axis) -> bool:
            return rest_rows_hold(d, axis, lag, tau_s, d_safe, gamma1, gamma3, accel_err,
                                  vertical_scale)

        lo = d_safe * (vertical_scale if axis == 2 else 1.0)  # h ≤ 0 there: rows cannot hold
        hi = max(2.0 * lo, 1.0)
        while not ok(hi):
            lo, hi = hi, 2.0 * hi
            if hi > d_max:
                return float("inf")
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            if ok(mid):
                hi = mid
            else:
                lo = mid
        worst = max(worst, hi)
    return worst
