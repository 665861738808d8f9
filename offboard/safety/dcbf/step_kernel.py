"""The dcbf filter's rows of one step in one compiled call (``Method.DCBF``; docs/safety.md).

:func:`dcbf_filter_rows_into` chains, in one call, the kernels the filter used to call
one by one from Python: the barrier now (:func:`offboard.safety.pair_kernel.barrier_kernel`), its
minimum, the deadlock breaker (:func:`offboard.safety.pair_kernel.tangential_kernel`), the
budget share per pair, the other agents' accelerations
(:func:`offboard.safety.dcbf.kernel.other_term_kernel`), the pair rows
(:func:`offboard.safety.dcbf.kernel.dcbf_rows_kernel`) and the ground rows
(:func:`offboard.safety.dcbf.kernel.ground_rows_kernel`). It calls those same kernels with the
same arguments, so it gives the same bits as the chain of calls it replaced
(``tests/unit/safety/test_dcbf_step_kernel.py``); what it saves is a dozen Python-level calls and
temporary arrays per follower step. It writes the rows into the filter's own buffers, so
no new array is boxed for them.

Its arguments travel in five typed groups (``typing.NamedTuple``, which numba passes as
one tuple of arrays and scalars): the step's pair rows (:class:`PairRows`), the own
motion (:class:`OwnMotion`), the ground barrier's input (:class:`GroundInput`), the
filter's parameters, lag tables and per-pair state (:class:`RowsState`) and the output
buffers (:class:`RowsOut`). The scalar parameters travel in one array, laid out by the
``P_*`` indices below (:func:`dcbf_params`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from offboard.safety.dcbf.kernel import dcbf_rows_kernel, ground_rows_kernel, other_term_kernel
from offboard.safety.pair_kernel import FULL_SHARE, SPLIT_SHARE, barrier_kernel, tangential_kernel
from swarm_common.jit import kernel

# layout of the parameter array (dcbf_params)
P_TAU = 0  # look-ahead τ of the barrier (s)
P_D_SAFE = 1  # safety distance D (m)
P_GAMMA1 = 2  # α(h) = γ1 h + γ3 h³: γ1 (1/s)
P_GAMMA3 = 3  # γ3 (1/(m⁴ s))
P_ACCEL_ERR = 4  # ē, bound on the relative-acceleration error (m/s²)
P_SIDE_GAIN = 5  # deadlock breaker gain (m/s²)
P_SIDE_H = 6  # barrier value below which it acts (m²)
P_DT = 7  # control period (s)
P_SMOOTH = 8  # low-pass weight of the previous relative-acceleration estimate
P_GROUND_GAMMA = 9  # the ground barrier's class-K gain (1/s)
P_GROUND_ERR = 10  # error bound on the predicted own vertical acceleration (m/s²)
P_HORIZON = 11  # prediction horizon T = τ_rp + dt (s)
# ē of the second set of pair rows, the trust region's tight ones (m/s²; 0: none this
# step; offboard.safety.dcbf.trust), written before each step
P_ALT_ERR = 12
# κ ≥ 1: the pair barrier's vertical scale, safe set outside the ellipsoid (D, D, κD)
# (docs/safety.md §4c); 1 = the sphere
P_VERT_SCALE = 13
N_PARAMS = 14
# RowsOut's second set of rows when there is none (never written)
NO_ALT_G = np.zeros((0, 3))
NO_ALT_RHS = np.zeros(0)


class PairRows(NamedTuple):
    """The M pair rows of one step."""

    dp: np.ndarray  # (M,3) Δp = p_i − p_j (m)
    dv: np.ndarray  # (M,3) Δv = v_i − v_j (m/s)
    pairs: np.ndarray  # (M,) int64 scenario index j
    full_share: np.ndarray  # (M,) bool: this agent takes the whole budget (share 1, else ½)
    predicted: np.ndarray  # (M,) bool: the row comes from prediction, not sensing
    margin: np.ndarray  # (M,) distance margin (m) added to D
    other_acc: np.ndarray  # (M,3) the other's broadcast acceleration estimate (m/s²)


class OwnMotion(NamedTuple):
    """The own agent's inner-loop model and disturbance estimate, each (3,) (m/s²)."""

    a_real: np.ndarray  # realised virtual control now
    u_prev: np.ndarray  # the previous command
    a_mean: np.ndarray  # mean realised control over the last period
    w_safe: np.ndarray  # disturbance estimate saturated at W_SAFE


class GroundInput(NamedTuple):
    """The ground barrier: ``on`` adds its two rows for altitude ``z`` (m), vertical
    velocity ``vz`` (m/s) and ``floor`` (m)."""

    on: bool
    z: float
    vz: float
    floor: float


class RowsState(NamedTuple):
    """The filter's constant tables and per-index state (:class:`DcbfFilter`)."""

    params: np.ndarray  # (N_PARAMS,) the ``P_*`` scalars
    lag: np.ndarray  # (6,3) lag table of LagCoefficients
    sens: np.ndarray  # (3,2,3) its sensitivities
    prev_dv: np.ndarray  # (N,3) Δv sensed the step before, per scenario index
    prev_ok: np.ndarray  # (N,) bool: prev_dv valid
    rel_acc: np.ndarray  # (N,3) low-passed relative acceleration
    rel_ok: np.ndarray  # (N,) bool: rel_acc valid


class RowsOut(NamedTuple):
    """The caller's buffers for the rows ``gᵀu ≥ r`` and the sidestep, and for the second
    set of rows, with the margin ``params[P_ALT_ERR]`` (written only where that is > 0)."""

    g: np.ndarray  # (≥ K, 3)
    rhs: np.ndarray  # (≥ K,) (m/s²)
    side: np.ndarray  # (3,) sidestep (m/s²)
    g_alt: np.ndarray = NO_ALT_G  # (≥ K, 3) where used
    rhs_alt: np.ndarray = NO_ALT_RHS  # (≥ K,) (m/s²) where used


def dcbf_params(
    tau_s: float, d_safe: float, gamma1: float, gamma3: float, accel_err: float,
    side_gain: float, side_h: float, dt: float, smooth: float, ground_gamma: float,
    ground_err: float, horizon: float, alt_err: float = 0.0, vertical_scale: float = 1.0,
) -> np.ndarray:
    """The parameter array of :func:`dcbf_filter_rows_into` (units at the ``P_*``)."""
    out = np.empty(N_PARAMS)
    out[P_ALT_ERR], out[P_VERT_SCALE] = alt_err, vertical_scale
    out[P_TAU], out[P_D_SAFE], out[P_GAMMA1], out[P_GAMMA3] = tau_s, d_safe, gamma1, gamma3
    out[P_ACCEL_ERR], out[P_SIDE_GAIN], out[P_SIDE_H] = accel_err, side_gain, side_h
    out[P_DT], out[P_SMOOTH], out[P_GROUND_GAMMA] = dt, smooth, ground_gamma
    out[P_GROUND_ERR], out[P_HORIZON] = ground_err, horizon
    return out


@kernel
def _min_or_nan(h: np.ndarray) -> float:
    """``float(h.min())`` as numpy gives it (nan if any element is nan), inf if empty."""
    out = math.inf
    for i in range(h.shape[0]):
        if math.isnan(h[i]):
            return math.nan
        if h[i] < out:
            out = h[i]
    return out


@kernel
def _scaled_barrier(dp: np.ndarray, dv: np.ndarray, tau: float, d_safe: float,
                    vertical_scale: float) -> np.ndarray:
    """:func:`barrier_kernel` of S Δp, S Δv, S = diag(1, 1, 1/κ) (m²): the pair barrier
    with vertical scale κ = ``vertical_scale`` (exactly :func:`barrier_kernel` for κ = 1)."""
    if vertical_scale == 1.0:
        return barrier_kernel(dp, dv, tau, d_safe)
    sdp = np.empty((dp.shape[0], 3))
    sdv = np.empty((dp.shape[0], 3))
    for i in range(dp.shape[0]):
        for c in range(3):
            sdp[i, c] = dp[i, c]
            sdv[i, c] = dv[i, c]
        sdp[i, 2] = dp[i, 2] / vertical_scale
        sdv[i, 2] = dv[i, 2] / vertical_scale
    return barrier_kernel(sdp, sdv, tau, d_safe)


@kernel
def dcbf_filter_rows_into(
    rows: PairRows, own: OwnMotion, ground: GroundInput, state: RowsState, out: RowsOut,
) -> tuple[int, float]:
    """The K = 2M [+2] rows of one dcbf step, ``g_iᵀu ≥ r_i``, into the caller's buffers
    ``out`` (no new arrays boxed per step): g in the first K rows of ``out.g``, r (m/s²)
    in those of ``out.rhs``, the sidestep (m/s²) in ``out.side``. Returns (K, h_min (m²));
    buffers too small are refused before any state is touched. Where ``params[P_ALT_ERR]``
    > 0, the same K rows with that margin ē instead of ``P_ACCEL_ERR``'s (the pair rows;
    the ground's are the same) go to ``out.g_alt``, ``out.rhs_alt``: the other agents'
    accelerations, and the state they update, are computed once for both.

    ``rows`` the M pair rows, ``own`` the own motion; when ``ground.on`` the two ground
    rows follow the pair rows. With ``params[P_VERT_SCALE]`` κ > 1 the pair barrier is the
    ellipsoidal one (:func:`_scaled_barrier`): h_min, the sidestep's weights and the pair
    rows; the sidestep's direction stays the tangent of Δp itself. ``state``: the
    parameters, the lag table and sensitivities
    of :class:`offboard.safety.dcbf.model.LagCoefficients` and the per-index state of
    :func:`offboard.safety.dcbf.kernel.other_term_kernel`, read and updated in place.
    """
    # unpacked by position, so plain tuples in the groups' order serve as well (numba
    # types a NamedTuple argument from Python on its slow path: :mod:`.front`)
    dp, dv, pairs, full_share, predicted, margin, other_acc = rows
    a_real, u_prev, a_mean, w_safe = own
    ground_on, z, vz, floor = ground
    params, lag, sens, prev_dv, prev_ok, rel_acc, rel_ok = state
    g_out, r_out, side_out, g_alt, r_alt = out
    m = dp.shape[0]
    k = 2 * m + 2 if ground_on else 2 * m
    if g_out.shape[0] < k or r_out.shape[0] < k or g_out.shape[1] != 3 or side_out.shape[0] != 3:
        raise ValueError("dcbf_filter_rows_into: buffers smaller than the rows")
    alt = params[P_ALT_ERR] > 0.0
    if alt and (g_alt.shape[0] < k or r_alt.shape[0] < k or g_alt.shape[1] != 3):
        raise ValueError("dcbf_filter_rows_into: buffers smaller than the rows")
    tau = params[P_TAU]
    kappa = params[P_VERT_SCALE]
    h = _scaled_barrier(dp, dv, tau, params[P_D_SAFE], kappa)
    h_min = _min_or_nan(h)
    for c in range(3):
        side_out[c] = 0.0
    if params[P_SIDE_GAIN] > 0.0 and m > 0:
        side = tangential_kernel(dp, h, params[P_SIDE_GAIN], params[P_SIDE_H])
        for c in range(3):
            side_out[c] = side[c]
    share = np.empty(m)
    d = np.empty(m)
    for i in range(m):
        share[i] = FULL_SHARE if full_share[i] else SPLIT_SHARE
        d[i] = params[P_D_SAFE] + margin[i]
    other = other_term_kernel(
        pairs, predicted, dv, other_acc, w_safe, a_mean, params[P_DT], params[P_SMOOTH],
        prev_dv, prev_ok, rel_acc, rel_ok,
    )
    g, rhs = dcbf_rows_kernel(
        dp, dv, a_real, u_prev, other, share, d, lag, sens, params[P_HORIZON], tau,
        params[P_GAMMA1], params[P_GAMMA3], params[P_ACCEL_ERR], kappa,
    )
    for r in range(2 * m):
        r_out[r] = rhs[r]
        for c in range(3):
            g_out[r, c] = g[r, c]
    if alt:
        g2, rhs2 = dcbf_rows_kernel(
            dp, dv, a_real, u_prev, other, share, d, lag, sens, params[P_HORIZON], tau,
            params[P_GAMMA1], params[P_GAMMA3], params[P_ALT_ERR], kappa,
        )
        for r in range(2 * m):
            r_alt[r] = rhs2[r]
            for c in range(3):
                g_alt[r, c] = g2[r, c]
    if ground_on:
        gg, rg = ground_rows_kernel(
            z, vz, a_real[2], w_safe[2], floor, params[P_HORIZON],
            lag[5, 2], lag[4, 2], lag[3, 2], lag[2, 2], lag[1, 2], lag[0, 2], tau,
            params[P_GROUND_GAMMA],
            params[P_GROUND_ERR],
        )
        for r in range(2):
            r_out[2 * m + r] = rg[r]
            for c in range(3):
                g_out[2 * m + r, c] = gg[r, c]
                if alt:
                    g_alt[2 * m + r, c] = gg[r, c]
            if alt:
                r_alt[2 * m + r] = rg[r]
    return k, h_min
