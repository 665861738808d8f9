"""The dcbf filter's rows as Python functions of arrays (test-only): the numpy prediction
``predict`` and the wrappers ``dcbf_rows``, ``ground_rows`` that shape their arguments
for the compiled kernels (:func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel`,
:func:`offboard.safety.dcbf.kernel.ground_rows_kernel`). The product calls the kernels
directly (:func:`offboard.safety.dcbf.step_kernel.dcbf_filter_rows_into`); the tests
check the rows through these against finite differences and numpy formulations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offboard.safety.dcbf.kernel import dcbf_rows_kernel, ground_rows_kernel
from offboard.safety.dcbf.model import LagCoefficients
from swarm_common.fastnp import einsum, f64, rows3, vec3


@dataclass
class Prediction:
    """Relative state T ahead and the barrier terms there (rows over pairs)."""

    dp: np.ndarray  # (M,3) Δp̂_T (m)
    dv: np.ndarray  # (M,3) Δv̂_T (m/s)
    da: np.ndarray  # (M,3) Δâ_T (m/s²)
    h: np.ndarray  # (M,) ĥ_T (m²)
    hdot: np.ndarray  # (M,) ḣ at x̂_T (m²/s)


def predict(
    dp: np.ndarray, dv: np.ndarray, a0: np.ndarray, u: np.ndarray, a_other: np.ndarray,
    lag: LagCoefficients, tau_s: float, d_safe: float | np.ndarray,
) -> Prediction:
    """Predict Δp, Δv, Δa T ahead: own a from a0 (3,) toward u (3,) through the lag, the
    other agent at constant acceleration a_other (M,3); h and ḣ (§2.3) there."""
    t = lag.T
    own_v = lag.ia * a0 + lag.cv * u
    own_p = lag.iia * a0 + lag.cp * u
    own_a = lag.ea * a0 + lag.ca * u
    pv = dv + own_v[None, :] - a_other * t
    pp = dp + dv * t + own_p[None, :] - 0.5 * a_other * t * t
    pa = own_a[None, :] - a_other
    vp = einsum("ij,ij->i", pv, pp)
    h = einsum("ij,ij->i", pp, pp) + 2.0 * tau_s * vp - d_safe**2
    hdot = 2.0 * vp + 2.0 * tau_s * (
        einsum("ij,ij->i", pv, pv) + einsum("ij,ij->i", pp, pa)
    )
    return Prediction(pp, pv, pa, h, hdot)


def dcbf_rows(
    dp: np.ndarray, dv: np.ndarray, a0: np.ndarray, u_ref: np.ndarray, a_other: np.ndarray,
    share: np.ndarray, lag: LagCoefficients, tau_s: float, d_safe: float | np.ndarray,
    gamma1: float, gamma3: float, accel_err: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``gᵀu ≥ r`` (2M of them, g unit length, r in m/s²): first the M (C1) rows, then
    the M (C2) rows, pair by pair in the order of ``dp``.

    With α(h) = γ1 h + γ3 h³ and h0 the barrier now, two conditions per pair:

    * (C1) ``f(u) = ḣ_T − ‖∂ḣ_T/∂a‖ ē + α(ĥ_T − ‖∂ĥ_T/∂a‖ ē) ≥ 0`` (the CBF condition at
      x̂_T of :func:`predict`; α increasing, so the error enters α exactly, not through
      α'(ĥ_T), which for the cubic term made every pair within ≈ 2.9 m repel:
      docs/safety.md §4);
    * (C2) ``ĥ_T − ‖∂ĥ_T/∂a‖ ē ≥ h0 − min(T α(h0), h0/2)`` (h0 > 0; ``h0 − T α(h0)``
      for h0 ≤ 0, which demands growth): h does not dip over the horizon.

    Each linearised at ``u_ref``: ``gᵀ(u − u_ref) ≥ −share·c(u_ref)``. ``ē`` (m/s²) bounds
    the error of the assumed relative acceleration over [0, T] (model, estimates). The
    sensitivities are those of ``lag.sens``: [0] a constant relative-acceleration error e
    over [0, T] (moves Δv̂ by eT, Δp̂ by eT²/2), [1] the command u through the lag.
    Computed by the compiled :func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel`.
    """
    m = len(dp)
    d = (np.full(m, float(d_safe)) if isinstance(d_safe, float | int)
         else np.asarray(d_safe, dtype=float))
    return dcbf_rows_kernel(
        rows3(dp), rows3(dv), vec3(a0), vec3(u_ref), rows3(a_other), f64(share), f64(d),
        lag.table, lag.sens3, lag.T, float(tau_s), float(gamma1), float(gamma3),
        float(accel_err),
    )


def ground_rows(
    z: float, vz: float, a0z: float, wz: float, floor: float, lag: LagCoefficients,
    tau_s: float, gamma1: float, accel_err: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Two rows ``gᵀu ≥ r`` (g = e_z) keeping an airborne agent above ``floor`` (m).

    The ground barrier ``h_g = z − floor + τ v_z`` (m; τ = ``tau_s``, the same look-ahead
    as the pair barrier) is linear in the state, so its prediction T ahead is linear in
    u_z and the rows are exact (no linearisation): with the z-axis lag coefficients,
    own disturbance ``wz`` (m/s²) held and the error bound ē on the vertical
    acceleration over [0, T] (compiled: :func:`offboard.safety.dcbf.kernel.ground_rows_kernel`)::

        ẑ_T = z + v_z T + iia a0 + cp u_z + wz T²/2,  v̂_T = v_z + ia a0 + cv u_z + wz T
        â_T = E a0 + ca u_z + wz
        (C1) v̂_T + τ â_T − ē(T + τ) + γ1 (ĥ_gT − ē(T²/2 + τT)) ≥ 0
        (C2) ĥ_gT − ē(T²/2 + τT) ≥ h_g0 − min(T γ1 h_g0, h_g0/2)    (h_g0 − Tγ1h_g0 if ≤ 0)
    """
    k = 2
    return ground_rows_kernel(
        float(z), float(vz), float(a0z), float(wz), float(floor), float(lag.T),
        float(lag.iia[k]), float(lag.ia[k]), float(lag.ea[k]), float(lag.cp[k]),
        float(lag.cv[k]), float(lag.ca[k]), float(tau_s), float(gamma1), float(accel_err),
    )
