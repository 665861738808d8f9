"""The per-step terms of the in-flight monitor (:mod:`offboard.safety.monitor`) in one
compiled call: the consistency residual, the estimated speed and the pairs first sensed
this step. Numbers and units are the monitor's; its module docstring gives the maths.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel


@kernel
def monitor_terms(z1: np.ndarray, z2: np.ndarray, est_p: np.ndarray, usable: np.ndarray,
                  rel_p: np.ndarray, fresh: np.ndarray, sel: np.ndarray,
                  sensed: np.ndarray, prev: np.ndarray, new: np.ndarray,
                  range_m: float) -> tuple[float, float, bool]:
    """One step's (residual (m), ‖z2‖ (m/s), any newly sensed pair).

    ``z1``, ``z2`` (3,): this agent's position and velocity estimates; ``est_p`` (N,3) the
    others' position estimates at the same time, ``usable`` (N,) bool where they may be
    read; ``rel_p`` (N,3) the sensed p_j − p_i where ``fresh`` (N,) bool; ``sel`` the
    indices of the pairs the filter uses this step. Writes ``sensed`` (N,) bool from
    ``sel``, ``new`` (N,) = ``sensed`` ∧ ¬``prev``, then copies ``sensed`` into ``prev``.

    The residual is the largest over the usable fresh rows of ‖z1 − (est_p[j] − rel_p[j])‖
    and over the usable rows neither fresh nor sensed of max(0, ``range_m`` −
    ‖est_p[j] − z1‖): NaN when no row counts, or when any counted row is NaN.
    """
    n = est_p.shape[0]
    for j in range(n):
        sensed[j] = False
    for s in sel:
        sensed[s] = True
    res = -math.inf
    counted = False
    nan = False
    for j in range(n):
        if not usable[j]:
            continue
        if fresh[j]:
            dx = z1[0] - (est_p[j, 0] - rel_p[j, 0])
            dy = z1[1] - (est_p[j, 1] - rel_p[j, 1])
            dz = z1[2] - (est_p[j, 2] - rel_p[j, 2])
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
        elif not sensed[j]:
            dx = est_p[j, 0] - z1[0]
            dy = est_p[j, 1] - z1[1]
            dz = est_p[j, 2] - z1[2]
            r = range_m - math.sqrt(dx * dx + dy * dy + dz * dz)
            if r < 0.0:  # NaN stays NaN
                r = 0.0
        else:
            continue
        counted = True
        if math.isnan(r):
            nan = True
        elif r > res:
            res = r
    if not counted or nan:
        res = math.nan
    any_new = False
    for j in range(n):
        new[j] = sensed[j] and not prev[j]
        any_new = any_new or new[j]
        prev[j] = sensed[j]
    speed = math.sqrt(z2[0] * z2[0] + z2[1] * z2[1] + z2[2] * z2[2])
    return res, speed, any_new
