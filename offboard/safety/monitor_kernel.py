"""The per-step terms of the in-flight monitor (:mod:`offboard.safety.monitor`) in one
compiled call (:func:`monitor_step`): the consistency residual, the estimated speed and the
pairs first sensed this step (:func:`monitor_terms`), and the residual's persistence rule
(:func:`residual_persist`). Numbers and units are the monitor's; its module docstring gives
the maths.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel

# :func:`monitor_terms`' marks of the sensed set, one int8 per agent of the scenario
OUT, BEFORE, BOTH, NOW = 0, 1, 2, 3  # BEFORE between calls means "sensed at the last one"


@kernel
def monitor_terms(z1: np.ndarray, z2: np.ndarray, est_p: np.ndarray, have: np.ndarray,
                  peers: np.ndarray, rel_p: np.ndarray, fresh: np.ndarray, sel: np.ndarray,
                  mark: np.ndarray, prev: np.ndarray, n_prev: int, new: np.ndarray,
                  range_m: float) -> tuple[float, float, int]:
    """One step's (residual (m), ‖z2‖ (m/s), how many pairs are newly sensed), at a cost
    that follows the peers and the pairs, not the N agents of the scenario.

    ``z1``, ``z2`` (3,): this agent's position and velocity estimates; ``est_p`` (N, ≥ 3)
    the others' position estimates at the same time in its first three columns (the peer
    table's rows themselves, whose first columns are ẑ_j1), ``have`` (N,) bool where they
    may be read; ``peers`` (scenario indices, int64): the only rows that may count (the
    agents whose estimates this follower reads); ``rel_p`` (N,3) the sensed p_j − p_i where
    ``fresh`` (N,) bool; ``sel`` the indices of the pairs the filter uses this step.

    The sensed set is kept between calls in ``mark`` (N,) int8, BEFORE where sensed at the
    last call and OUT elsewhere, and in ``prev`` (≥ N_prev, int64), the last call's ``sel``
    in its first ``n_prev``. The indices of ``sel`` not sensed at the last call are written
    into ``new`` (≥ len(sel)) in ``sel``'s order, each once; then ``mark`` and ``prev``
    hold this call's set (the caller keeps ``n_prev = len(sel)``).

    The residual is the largest over the readable fresh peer rows of
    ‖z1 − (est_p[j] − rel_p[j])‖ and over the readable peer rows neither fresh nor sensed
    of max(0, ``range_m`` − ‖est_p[j] − z1‖): NaN when no row counts, or when any counted
    row is NaN.
    """
    n_new = 0
    for s in sel:
        if mark[s] == OUT:
            new[n_new] = s
            n_new += 1
            mark[s] = NOW
        elif mark[s] == BEFORE:
            mark[s] = BOTH
    for q in range(n_prev):
        if mark[prev[q]] == BEFORE:  # sensed before, not now
            mark[prev[q]] = OUT
    for q in range(sel.shape[0]):
        mark[sel[q]] = BEFORE  # for the rest of this call: sensed now
        prev[q] = sel[q]
    res = -math.inf
    counted = False
    nan = False
    for j in peers:
        if not have[j]:
            continue
        if fresh[j]:
            dx = z1[0] - (est_p[j, 0] - rel_p[j, 0])
            dy = z1[1] - (est_p[j, 1] - rel_p[j, 1])
            dz = z1[2] - (est_p[j, 2] - rel_p[j, 2])
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
        elif mark[j] == OUT:
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
    speed = math.sqrt(z2[0] * z2[0] + z2[1] * z2[1] + z2[2] * z2[2])
    return res, speed, n_new


# the persistence counters of :func:`residual_persist`, one int64 array per monitor
CTR_OVER, CTR_UNDER, CTR_RAISED, CTR_HELD, CTR_FALLBACK = range(5)


@kernel
def residual_persist(ctr: np.ndarray, residual: float, speed: float, z1: np.ndarray,
                     bound_m: float, v_max_mps: float, persist: int,
                     fallback_after: int) -> bool:
    """One step of the residual's persistence rule; returns whether RESIDUAL is raised.

    ``ctr`` (5,) int64 holds, at the ``CTR_*`` indices, the consecutive steps over the
    bound, under it while raised, the raised flag, the steps RESIDUAL has been held and the
    latched fallback flag (updated in place). A step is over when ``residual`` (m) is over
    ``bound_m``, ``speed`` (m/s) is not finite or over ``v_max_mps``, or ``z1`` (3,) is not
    finite; a step with a NaN residual that is not over leaves the counters as they are.
    ``persist`` steps over raise the flag and ``persist`` under clear it; ``fallback_after``
    steps held latch the fallback."""
    over = (residual > bound_m or not math.isfinite(speed) or speed > v_max_mps
            or not (math.isfinite(z1[0]) and math.isfinite(z1[1]) and math.isfinite(z1[2])))
    if over:
        ctr[CTR_OVER] += 1
        ctr[CTR_UNDER] = 0
    elif math.isfinite(residual):
        ctr[CTR_OVER] = 0
        ctr[CTR_UNDER] += 1
    if ctr[CTR_RAISED] == 0 and ctr[CTR_OVER] >= persist:
        ctr[CTR_RAISED] = 1
    elif ctr[CTR_RAISED] != 0 and ctr[CTR_UNDER] >= persist:
        ctr[CTR_RAISED] = 0
    if ctr[CTR_RAISED] != 0:
        ctr[CTR_HELD] += 1
    else:
        ctr[CTR_HELD] = 0
    if ctr[CTR_HELD] >= fallback_after:
        ctr[CTR_FALLBACK] = 1
    return ctr[CTR_RAISED] != 0


@kernel
def monitor_step(z1: np.ndarray, z2: np.ndarray, est_p: np.ndarray, have: np.ndarray,
                 peers: np.ndarray, rel_p: np.ndarray, fresh: np.ndarray, sel: np.ndarray,
                 mark: np.ndarray, prev: np.ndarray, n_prev: int, new: np.ndarray,
                 range_m: float, ctr: np.ndarray, bound_m: float, v_max_mps: float,
                 persist: int, fallback_after: int) -> tuple[float, int, bool]:
    """:func:`monitor_terms`, then :func:`residual_persist` of its residual and speed, in
    one call (arguments as theirs): (residual (m), pairs newly sensed, RESIDUAL raised)."""
    residual, speed, n_new = monitor_terms(z1, z2, est_p, have, peers, rel_p, fresh, sel,
                                           mark, prev, n_prev, new, range_m)
    raised = residual_persist(ctr, residual, speed, z1, bound_m, v_max_mps, persist,
                              fallback_after)
    return residual, n_new, raised
