"""The dcbf follower's transient speed limit (``controller.max_transient_speed_mps`` = v_t > 0;
docs/safety.md §5i).

Why: a pair gets barrier rows only once sensed, so the load-time check of the sensing range
(swarm_common.scenario.safety_check, (b)) needs a bound on the speed at which two agents
can close when they come into range. The nominal law has none: a follower far from its
vertex flies toward it as fast as its gains ask. These rows bound the follower's velocity
relative to its desired velocity v* (from the desired-state estimate ξ̂ it tracks),
e = v − v*, so that the check can take ‖e‖ ≤ v_t.

**Rows.** Over the dcbf horizon T = τ_rp + dt, with the per-axis lag of
:class:`~offboard.safety.dcbf.model.LagCoefficients` (the pair and world rows' model), the
predicted velocity is ``v̂_T = v + ia·a0 + w T + cv·u`` and the desired one
``v*_T = v* + a* T + j* T²/2`` (ξ̂'s jet), so ``ê_T = e0 + cv∘u`` with
``e0 = v + ia·a0 + w T − v*_T``, linear in u (cv > 0 per axis). The limit is the ball
``‖ê_T‖ ≤ b``, ``b = v_t − ē_w T`` (ē_w: the world rows' norm bound on the own
acceleration's error, so the true ‖e(T)‖ ≤ ‖ê_T‖ + ē_w T ≤ v_t). The QP gets it as
tangent planes (cuts) ``nᵀê_T ≤ b``, n a unit direction, i.e. ``−(n∘cv)ᵀu ≥ nᵀe0 − b``,
scaled to a unit gradient: the first at the direction of ê_T for the command tried first,
then, while the QP's answer is outside the ball, one more at the answer's direction
(cutting planes, at most :data:`MAX_CUTS`). If the answer is still outside, the inner cube
``|ê_T,a| ≤ b/√3`` (six rows) is added, whose every point is in the ball. So the answer
flown keeps ‖ê_T‖ ≤ b whenever the QP needs no slack: that, not the polytope, is the
guarantee.

**Feasibility.** A follower that is already faster than v_t (a fast start, or rows
dropped for the pair rows) must be allowed to slow down within the input set: each row's
right side is clipped to what ``u_b`` achieves, the command that steers ê_T to 0 projected
into the input set (a point of the set that keeps every clipped row). So these rows never
need the QP's slack on their own; with the others, the filter drops them rather than
relax a pair's, and flies the command nearest ``u_b`` that keeps the others
(:meth:`offboard.safety.dcbf.filter.DcbfFilter.solve_limited`).

**Only near the limit.** No row is added while the command tried first (u_nom plus the
sidestep) predicts ‖ê_T‖ ≤ NEAR·b and the QP's answer stays in the ball: a run that stays
below NEAR·b is bit for bit the run without the key.
"""

from __future__ import annotations

import math

import numpy as np

from offboard.safety.base import W_SAFE
from offboard.safety.dcbf.kernel import project_into, saturate_into
from offboard.safety.dcbf.model import LagCoefficients, ProjectedInputSet
from swarm_common.fastnp import f64, norm, vec3
from swarm_common.jit import CallSite, kernel

NEAR = 0.8  # a first cut is added once the tried command predicts this fraction of b
TOL = 1e-6  # m/s: an answer this little outside the ball needs no further cut (rounding)
MAX_CUTS = 3  # tangent planes before the inner cube is added


_SQRT3 = math.sqrt(3.0)


@kernel
def prepare_kernel(v: np.ndarray, a0: np.ndarray, w: np.ndarray, xi: np.ndarray,
                   ia: np.ndarray, cv: np.ndarray, t: float, w_safe: float,
                   proj: np.ndarray, cos_a: np.ndarray, sin_a: np.ndarray,
                   e0: np.ndarray, u_b: np.ndarray) -> None:
    """:meth:`TransientLimit.prepare` into ``e0`` and ``u_b`` (3,): the same operations in
    numpy's order (``w`` saturated at ``w_safe`` by
    :func:`~offboard.safety.dcbf.kernel.saturate_into`; ``u_b`` projected by
    :func:`offboard.safety.dcbf.kernel.project_into`)."""
    ws = np.empty(3)
    saturate_into(w, w_safe, ws)
    for k in range(3):
        v_star = (xi[3 + k] + xi[6 + k] * t) + (0.5 * xi[9 + k]) * (t * t)
        e0[k] = ((v[k] + ia[k] * a0[k]) + ws[k] * t) - v_star
        u_b[k] = (-e0[k]) / cv[k]
    project_into(u_b, proj, cos_a, sin_a)


@kernel
def write_kernel(cuts: np.ndarray, n_cuts: int, cube: bool, cv: np.ndarray, e0: np.ndarray,
                 u_b: np.ndarray, bound: float, g: np.ndarray, rhs: np.ndarray,
                 start: int) -> int:
    """:meth:`TransientLimit.write` of the first ``n_cuts`` rows of ``cuts`` (unit normals)
    and, with ``cube``, the inner cube's six planes; returns the rows written."""
    rows = n_cuts + (6 if cube else 0)
    # three work vectors for every row: no array made or viewed in the loop, where numba
    # would allocate and count references on each row (the same operations, in order)
    nv, grad, g_r = np.empty(3), np.empty(3), np.empty(3)
    for i in range(rows):
        if i < n_cuts:
            for k in range(3):
                nv[k] = cuts[i, k]
            b = bound
        else:
            a = i - n_cuts
            for k in range(3):
                nv[k] = 0.0
            nv[a % 3] = 1.0 if a < 3 else -1.0
            b = bound / _SQRT3
        for k in range(3):
            grad[k] = -(nv[k] * cv[k])
        size = math.sqrt(np.dot(grad, grad))
        r = start + i
        for k in range(3):
            g[r, k] = grad[k] / size
            g_r[k] = g[r, k]
        need = (np.dot(nv, e0) - b) / size
        rhs[r] = min(need, np.dot(g_r, u_b))
    return rows


class TransientLimit:
    """One follower's speed rows (module docstring): :meth:`prepare` each step, then
    :meth:`excess` to test a command and :meth:`write` to append rows."""

    def __init__(self, v_t: float, lag: LagCoefficients, err: float,
                 uset: ProjectedInputSet) -> None:
        if v_t <= 0.0:
            raise ValueError("TransientLimit: max_transient_speed_mps must be > 0")
        self.v_t = float(v_t)
        self.T = float(lag.T)
        self.ia = lag.ia.copy()
        self.cv = lag.cv.copy()
        self.uset = uset
        # the ball's radius for ê_T; ≥ 0 (a zero radius asks ê_T = 0, clipped to what u can do)
        self.bound = max(0.0, self.v_t - float(err) * self.T)
        self.e0 = np.zeros(3)  # ê_T at u = 0 (m/s)
        self.u_b = np.zeros(3)  # the command toward ê_T = 0, in the input set (m/s²)
        self._prepare = CallSite(prepare_kernel)  # its arguments' types are fixed

    def prepare(self, v: np.ndarray, a0: np.ndarray, w: np.ndarray, xi: np.ndarray) -> None:
        """The step's ê_T at u = 0 from the own velocity ``v`` (m/s), realised acceleration
        ``a0`` and disturbance estimate ``w`` (m/s², saturated at W_SAFE here, as for the
        world rows), and the desired state ``xi`` (12,) the nominal law tracks; and ``u_b``."""
        e0, u_b = np.empty(3), np.empty(3)  # new arrays: callers may keep the last ones
        proj, cos_a, sin_a = self.uset.projection
        self._prepare.call(vec3(v), vec3(a0), vec3(w), f64(xi), self.ia, self.cv, self.T, W_SAFE,
                       proj, cos_a, sin_a, e0, u_b)
        self.e0, self.u_b = e0, u_b

    def predicted(self, u: np.ndarray) -> np.ndarray:
        """ê_T (3,) (m/s) for the command ``u`` (m/s²)."""
        return self.e0 + self.cv * u

    def excess(self, u: np.ndarray) -> float:
        """‖ê_T(u)‖ − b (m/s): > 0 is outside the ball."""
        return norm(self.predicted(u)) - self.bound

    def near(self, u: np.ndarray) -> bool:
        """Whether ``u`` predicts ‖ê_T‖ > NEAR·b (a first cut is due)."""
        return norm(self.predicted(u)) > NEAR * self.bound

    def direction(self, u: np.ndarray) -> np.ndarray:
        """The unit direction of ê_T(u) (a cut's normal; any unit vector at ê_T = 0)."""
        e = self.predicted(u)
        n = norm(e)
        return e / n if n > 0.0 else np.array([1.0, 0.0, 0.0])

    def write(self, cuts: list[np.ndarray], cube: bool, g: np.ndarray, rhs: np.ndarray,
              start: int) -> int:
        """The rows ``gᵀu ≥ r`` of the ``cuts`` (unit normals n: nᵀê_T ≤ b) and, with
        ``cube``, of the inner cube (±e_a: ±ê_T,a ≤ b/√3), into ``g``, ``rhs`` from row
        ``start``; each clipped to what ``u_b`` achieves. Returns how many."""
        rows = len(cuts) + (6 if cube else 0)
        if start < 0 or start + rows > min(len(g), len(rhs)) or g.shape[1:] != (3,):
            raise ValueError(f"TransientLimit.write: {rows} rows from {start} do not fit "
                             f"buffers of {len(g)} and {len(rhs)}")
        normals = np.array(cuts, dtype=np.float64).reshape(len(cuts), 3)
        return int(write_kernel(normals, len(cuts), cube, self.cv, self.e0, self.u_b,
                                self.bound, g, rhs, int(start)))
