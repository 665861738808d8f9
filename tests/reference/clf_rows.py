"""The CLF terms and the RCBF rows as Python functions of arrays (test-only): wrappers
that shape their arguments for the compiled kernels
(:func:`offboard.safety.clf_kernel.clf_into`,
:func:`offboard.safety.rcbf.kernel.rcbf_rows_kernel`). The product calls the kernels
through :func:`offboard.safety.rcbf.clf_rcbf.clf_terms_of_reference` and
:func:`offboard.safety.rcbf.kernel.rcbf_filter_rows_kernel`; the tests build problems
from errors and pairs through these."""

from __future__ import annotations

import numpy as np

from offboard.safety.clf_kernel import CLF_OUT, clf_into
from offboard.safety.rcbf.clf_rcbf import (
    AW_BRAKE_SHARE,
    AW_RESERVE,
    NO_BOX,
    ClfTerms,
    barrier,
    clf_terms_from,
)
from offboard.safety.rcbf.kernel import RCBF_ROW_MARGIN, rcbf_rows_kernel
from swarm_common.fastnp import rows3, vec3


def clf_terms(
    e1: np.ndarray,
    e2: np.ndarray,
    w: np.ndarray,
    a_ref: np.ndarray,
    kp: float,
    kd: float,
    lam: float,
    ks: float,
    box: tuple[np.ndarray, np.ndarray] | None = None,
) -> ClfTerms:
    """CLF of Departure 10 and the nominal formation controller (see module docstring);
    with ``box`` = (lo, hi) (m/s², per axis) the nominal control has anti-windup
    (docs/saturation.md §2) and lies in the box. Compiled:
    :func:`offboard.safety.clf_kernel.clf_into`."""
    lo, hi = box if box is not None else (NO_BOX, NO_BOX)
    out = np.empty(CLF_OUT)
    clf_into(
        vec3(e1), vec3(e2), vec3(w), vec3(a_ref), float(kp), float(kd), float(lam),
        float(ks), box is not None, vec3(lo), vec3(hi), AW_BRAKE_SHARE, AW_RESERVE, out,
    )
    return clf_terms_from(out)


def rcbf_rows(
    dp: np.ndarray,
    dv: np.ndarray,
    w_i: np.ndarray,
    a_other: np.ndarray,
    share: np.ndarray,
    tau: float,
    d_safe: float,
    gamma: float,
    margin: float = RCBF_ROW_MARGIN,
    h: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RCBF rows ``n̂ᵀu ≥ r`` for agent i (Departures 12–13) and h per pair.

    dp, dv (M,3): Δp = p_i − p_j, Δv = v_i − v_j; w_i (3,): own lumped disturbance
    estimate; a_other (M,3): other agent's acceleration taken as known (leaders'
    broadcast, zeros for followers); share (M,): 0.5 follower–follower, 1.0 vs leader.
    ``margin`` (m/s²) tightens the rows against solver tolerance. Compiled
    (:func:`offboard.safety.rcbf.kernel.rcbf_rows_kernel`).
    """
    dp, dv, a_other = rows3(dp), rows3(dv), rows3(a_other)
    share = np.ascontiguousarray(share, float)
    if not len(dv) == len(a_other) == len(share) == len(dp):  # the kernels read unchecked
        raise ValueError("rcbf_rows: dp, dv, a_other, share and h differ in length")
    h = barrier(dp, dv, tau, d_safe) if h is None else np.ascontiguousarray(h, float)
    if len(h) != len(dp):
        raise ValueError("rcbf_rows: dp, dv, a_other, share and h differ in length")
    n_hat, rhs = rcbf_rows_kernel(dp, dv, vec3(w_i), a_other, share, h, float(tau),
                                  float(gamma), float(margin))
    return n_hat, rhs, h
