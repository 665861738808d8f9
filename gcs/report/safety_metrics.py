"""Offline safety metrics from a run's ground truth (series.npz ``p``, ``v``, ``u``).

The TRUE barrier ``h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D²`` (§2.3) of every pair with at least one
follower, and how often the commanded u was not what the setpoint realises (tilt/thrust
clip of :func:`swarm_common.frames.accel_to_attitude`). Used by bench/safety_sweep.py and
the dcbf integration test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offboard.inner_loop.attitude import accel_from_attitude, setpoint_from_accel
from swarm_common.barrier import vertically_scaled
from swarm_common.scenario.model import VehicleConfig


@dataclass
class TrueBarrier:
    """True-h statistics over a run."""

    h_min: float  # m², smallest true h over all follower pairs and steps
    neg_pair_steps: int  # (pair, step) samples with true h < 0
    neg_follower_frac: float  # fraction of follower-steps whose smallest h is < 0
    dist_min: float  # m, smallest pair distance at the control samples


def true_barrier(
    p: np.ndarray, v: np.ndarray, follower_idx: list[int], tau: float, d_safe: float,
    vertical_scale: float = 1.0,
) -> TrueBarrier:
    """Statistics of the true h from p, v (K,N,3) for pairs with a follower; with
    ``vertical_scale`` κ > 1 the ellipsoidal h of docs/safety.md §4c (the distance stays
    Euclidean)."""
    n = p.shape[1]
    fol = set(follower_idx)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if i in fol or j in fol]
    ii = np.array([a for a, _ in pairs])
    jj = np.array([b for _, b in pairs])
    dp = p[:, ii] - p[:, jj]
    dv = v[:, ii] - v[:, jj]
    sdp, sdv = vertically_scaled(dp, vertical_scale), vertically_scaled(dv, vertical_scale)
    h = np.einsum("kmc,kmc->km", sdp, sdp) + 2.0 * tau * np.einsum("kmc,kmc->km", sdv, sdp)
    h -= d_safe**2
    neg = h < 0.0
    fol_neg = np.zeros((p.shape[0], n), dtype=bool)
    for m, (a, b) in enumerate(pairs):
        fol_neg[:, a] |= neg[:, m]
        fol_neg[:, b] |= neg[:, m]
    frac = float(fol_neg[:, follower_idx].mean()) if follower_idx else 0.0
    dist = float(np.sqrt(np.einsum("kmc,kmc->km", dp, dp)).min())
    return TrueBarrier(float(h.min()), int(neg.sum()), frac, dist)


def clipped_steps(
    u: np.ndarray, follower_idx: list[int], veh: VehicleConfig, tol: float = 1e-3,
) -> int:
    """Follower-steps whose setpoint realises an acceleration > ``tol`` (m/s²) from u."""
    count = 0
    for k in range(u.shape[0]):
        for i in follower_idx:
            sp = setpoint_from_accel(u[k, i], 0.0, veh)
            real = accel_from_attitude(
                sp.roll, sp.pitch, sp.yaw, sp.thrust_n, veh.mass_kg, veh.gravity_mps2
            )
            if float(np.max(np.abs(real - u[k, i]))) > tol:
                count += 1
    return count
