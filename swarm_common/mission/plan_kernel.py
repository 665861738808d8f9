"""The compiled evaluation of a timed mission: every agent's jet at a time in one call.

A leader asks its plan for its desired state twice a control step. In Python that walk
(find the leg, the profile's jet, the pose, the agents) cost more than the rest of the
leader's step, so it is one kernel over a numeric table of the legs
(:func:`legs_table`). Every kernel repeats the Python formulation's operations in its order
(``bisect.bisect_right`` for the leg, ``x**n`` as the C library's ``pow``, products left to
right): the leaders' references did not change by a bit when it came in (course8, gap8 and
square27 over 20,000 times each, and their runs). ``tests/unit/mission/test_plan_kernel.py``
checks it against the poses and finite differences.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from swarm_common.jit import kernel
from swarm_common.mission.profile import sigma_jet_kernel

# columns of the legs table (one row per leg, :func:`legs_table`)
T0, DUR, ARRIVAL = 0, 1, 2
START_C, START_S, START_PSI = 3, 6, 7  # start pose: centroid (3 columns), scale, yaw (rad)
END_C, END_S, END_PSI = 8, 11, 12  # end pose: as the start's
TABLE_COLS = 13


class PoseLike(Protocol):
    """A formation pose as :class:`swarm_common.mission.plan.Pose` has it."""

    @property
    def centroid(self) -> np.ndarray: ...
    @property
    def scale(self) -> float: ...
    @property
    def yaw_rad(self) -> float: ...


class LegLike(Protocol):
    """A leg as :class:`swarm_common.mission.plan.Leg` has it."""

    @property
    def t0(self) -> float: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def arrival_s(self) -> float: ...
    @property
    def start(self) -> PoseLike: ...
    @property
    def end(self) -> PoseLike: ...


def legs_table(legs: Sequence[LegLike]) -> np.ndarray:
    """(L, :data:`TABLE_COLS`) the legs as numbers for :func:`plan_xi_kernel`."""
    tab = np.empty((len(legs), TABLE_COLS))
    for k, leg in enumerate(legs):
        tab[k, T0], tab[k, DUR], tab[k, ARRIVAL] = leg.t0, leg.duration_s, leg.arrival_s
        for col, pose in ((START_C, leg.start), (END_C, leg.end)):
            tab[k, col:col + 3] = pose.centroid
            tab[k, col + 3], tab[k, col + 4] = pose.scale, pose.yaw_rad
    return tab


def pose_row(pose: PoseLike) -> np.ndarray:
    """[cx, cy, cz, scale, yaw]: ``pose`` as :func:`plan_xi_kernel`'s ``start``."""
    return np.array([*pose.centroid, pose.scale, pose.yaw_rad], dtype=float)


@kernel
def agent_xi_kernel(
    c0: np.ndarray, dc: np.ndarray, s0: float, ds: float, psi0: float, dpsi: float,
    q: np.ndarray, st: np.ndarray, out: np.ndarray,
) -> None:
    """Every agent's time jet [p, ṗ, p̈, p⃛] into the rows of ``out`` (N, 12) on a moving
    leg (:mod:`swarm_common.mission.plan`'s docstring): centroid ``c0`` + σ ``dc``, scale
    ``s0`` + σ ``ds``, yaw ``psi0`` + σ ``dpsi`` (rad), offsets ``q`` (N, 3) m, ``st`` =
    [σ, σ_t, σ_tt, σ_ttt] (1/s^k)."""
    sig, s1, s2, s3 = st[0], st[1], st[2], st[3]
    scale = s0 + sig * ds
    e = cmath.exp(complex(0.0, psi0 + sig * dpsi))
    c_xy = complex(c0[0], c0[1])
    dc_xy = complex(dc[0], dc[1])
    k1 = complex(ds, scale * dpsi)
    k2 = complex(-scale * dpsi * dpsi, 2.0 * ds * dpsi)
    k3 = complex(-3.0 * ds * dpsi * dpsi, -scale * dpsi * dpsi * dpsi)
    for i in range(q.shape[0]):
        base = e * complex(q[i, 0], q[i, 1])
        p0 = c_xy + sig * dc_xy + scale * base
        p1 = dc_xy + k1 * base
        p2 = k2 * base
        p3 = k3 * base
        t1 = p1 * s1
        t2 = p2 * s1 * s1 + p1 * s2
        t3 = p3 * s1 * s1 * s1 + 3.0 * p2 * s1 * s2 + p1 * s3
        z1 = dc[2] + ds * q[i, 2]
        out[i, 0], out[i, 1], out[i, 2] = p0.real, p0.imag, c0[2] + sig * dc[2] + scale * q[i, 2]
        out[i, 3], out[i, 4], out[i, 5] = t1.real, t1.imag, z1 * s1
        out[i, 6], out[i, 7], out[i, 8] = t2.real, t2.imag, z1 * s2
        out[i, 9], out[i, 10], out[i, 11] = t3.real, t3.imag, z1 * s3


@kernel
def hold_xi_kernel(
    cx: float, cy: float, cz: float, scale: float, yaw: float, q: np.ndarray, out: np.ndarray,
) -> None:
    """Every agent at rest at the pose (centroid m, scale, yaw rad): positions
    ``c + s Rz(yaw) q`` in columns 0-2 of ``out`` (N, 12), zeros elsewhere."""
    c, s = math.cos(yaw), math.sin(yaw)
    for i in range(q.shape[0]):
        for k in range(12):
            out[i, k] = 0.0
        out[i, 0] = cx + scale * (c * q[i, 0] - s * q[i, 1])
        out[i, 1] = cy + scale * (s * q[i, 0] + c * q[i, 1])
        out[i, 2] = cz + scale * q[i, 2]


@kernel
def plan_xi_kernel(
    t: float, tab: np.ndarray, start: np.ndarray, q: np.ndarray, pw: np.ndarray,
    out: np.ndarray,
) -> None:
    """The jets (N, 12) into ``out`` of the agents of offsets ``q`` (N, 3) at time ``t``
    (s) of the plan whose legs are the rows of ``tab`` (L, :data:`TABLE_COLS`) and whose
    pose before the first leg is ``start`` = [cx, cy, cz, scale, yaw]: the leg found as
    ``bisect.bisect_right`` of the legs' start times finds it; moving, the profile's jet
    scaled by the leg's duration (``pw``: :data:`~swarm_common.mission.profile.POWERS`);
    else at rest at that leg's end pose."""
    lo, hi = 0, tab.shape[0]
    while lo < hi:  # bisect.bisect_right over tab[:, T0] (a NaN t lands after the last)
        mid = (lo + hi) // 2
        if t < tab[mid, T0]:
            hi = mid
        else:
            lo = mid + 1
    k = lo - 1
    if k < 0:
        hold_xi_kernel(start[0], start[1], start[2], start[3], start[4], q, out)
        return
    d = tab[k, DUR]
    if t < tab[k, ARRIVAL] and d > 0.0:
        raw = np.empty(4)
        sigma_jet_kernel((t - tab[k, T0]) / d, pw, raw)
        st = np.empty(4)
        st[0] = raw[0]
        st[1] = raw[1] / d
        st[2] = raw[2] / (d * d)
        st[3] = raw[3] / (d * d * d)
        dc = np.empty(3)
        for a in range(3):
            dc[a] = tab[k, END_C + a] - tab[k, START_C + a]
        agent_xi_kernel(tab[k, START_C:START_C + 3], dc, tab[k, START_S],
                        tab[k, END_S] - tab[k, START_S], tab[k, START_PSI],
                        tab[k, END_PSI] - tab[k, START_PSI], q, st, out)
        return
    hold_xi_kernel(tab[k, END_C], tab[k, END_C + 1], tab[k, END_C + 2], tab[k, END_S],
                   tab[k, END_PSI], q, out)
