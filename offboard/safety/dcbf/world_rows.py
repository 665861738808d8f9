"""The dcbf filter's world rows: one pair of barrier rows per half-space nᵀx ≥ c that the
agent keeps this step (an obstacle's tangent plane or a geofence face, box or polygon,
:func:`swarm_common.world.geometry.world_planes`; docs/world.md).

They are the ground barrier's rows (:func:`offboard.safety.dcbf.kernel.ground_rows_kernel`)
for a plane of any direction: with the barrier ``h = nᵀp − c + τ nᵀv`` (m) and the state
predicted T = τ_rp + dt ahead through each axis's lag (the lag coefficients of
:class:`offboard.safety.dcbf.model.LagCoefficients`; horizontal axes lag by τ_rp, the
vertical by τ_F), h_T is linear in u, so the rows are exact::

    (C1) nᵀv̂_T + τ nᵀâ_T − ē_n(T + τ) + γ (ĥ_T − ē_n(T²/2 + τT)) ≥ 0
    (C2) ĥ_T − ē_n(T²/2 + τT) ≥ h0 − min(Tγ h0, h0/2)     (h0 − Tγ h0 if h0 ≤ 0)

with ē_n = |n_z| ē_z + ‖n_xy‖ ē_xy the bound on the error of the predicted own
acceleration along n. Each row is scaled to a unit normal ‖g‖ = 1. The plane is taken
again each step from where the agent is: for a convex obstacle the distance to the
obstacle is never less than the distance to that plane, so keeping the plane's barrier
keeps the obstacle's.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel
from swarm_common.world.config import Geofence, World, make_world
from swarm_common.world.geometry import world_planes


@kernel
def plane_rows_into(
    normals: np.ndarray, offsets: np.ndarray, m: int, p: np.ndarray, v: np.ndarray,
    a0: np.ndarray, w: np.ndarray, lag: np.ndarray, t: float, tau: float, gamma: float,
    err_v: float, err_h: float, g_out: np.ndarray, r_out: np.ndarray, start: int,
) -> float:
    """Two rows ``gᵀu ≥ r`` per plane k < ``m`` of ``normals`` (P,3), ``offsets`` (P,) into
    ``g_out``, ``r_out`` from row ``start`` (module docstring): own position ``p`` (m),
    velocity ``v`` (m/s), realised acceleration ``a0`` and disturbance ``w`` (m/s²), the
    lag table ``lag`` (6,3) (ca, cv, cp, ea, ia, iia per axis) over T = ``t`` (s), the
    look-ahead ``tau`` (s), the gain ``gamma`` (1/s), the error bounds ``err_v`` (vertical)
    and ``err_h`` (horizontal, m/s²). Returns the smallest h0 (m; +inf for no plane)."""
    h_min = math.inf
    for k in range(m):
        s_p = 0.0
        s_v = 0.0
        s_a = 0.0
        s_now = 0.0
        for a in range(3):
            n = normals[k, a]
            s_p += n * (p[a] + v[a] * t + lag[5, a] * a0[a] + 0.5 * w[a] * t * t)
            s_v += n * (v[a] + lag[4, a] * a0[a] + w[a] * t)
            s_a += n * (lag[3, a] * a0[a] + w[a])
            s_now += n * (p[a] + tau * v[a])
        c = offsets[k]
        h_free = s_p - c + tau * s_v
        nz = abs(normals[k, 2])
        nh = math.sqrt(normals[k, 0] ** 2 + normals[k, 1] ** 2)
        err = nz * err_v + nh * err_h
        m_h = err * (0.5 * t * t + tau * t)
        h0 = s_now - c
        h_min = min(h_min, h0)
        drop = t * gamma * h0
        if h0 > 0.0:
            drop = min(0.5 * h0, drop)
        r1 = -(s_v + tau * s_a - err * (t + tau) + gamma * (h_free - m_h))
        r2 = h0 - drop - (h_free - m_h)
        n1 = 0.0
        n2 = 0.0
        for a in range(3):
            g1 = normals[k, a] * (lag[1, a] + tau * lag[0, a]
                                  + gamma * (lag[2, a] + tau * lag[1, a]))
            g2 = normals[k, a] * (lag[2, a] + tau * lag[1, a])
            g_out[start + 2 * k, a] = g1
            g_out[start + 2 * k + 1, a] = g2
            n1 += g1 * g1
            n2 += g2 * g2
        n1 = math.sqrt(n1)
        n2 = math.sqrt(n2)
        for a in range(3):
            g_out[start + 2 * k, a] /= n1
            g_out[start + 2 * k + 1, a] /= n2
        r_out[start + 2 * k] = r1 / n1
        r_out[start + 2 * k + 1] = r2 / n2
    return h_min


class WorldPlanes:
    """The half-spaces of one agent's world at each step (:func:`world_planes` of
    ``world`` within ``range_m``, m), in buffers kept for the agent's lifetime."""

    def __init__(self, world: World, range_m: float) -> None:
        self.table = np.ascontiguousarray(world.table, dtype=float)
        self.clearance = np.ascontiguousarray(world.clearances, dtype=float)
        fence, self.fence_margin = world.fence_arrays()
        self.fence = np.ascontiguousarray(fence, dtype=float)
        self.range_m = float(range_m)
        self.capacity = len(self.table) + len(self.fence)
        self.normals = np.zeros((self.capacity, 3))
        self.offsets = np.zeros(self.capacity)

    def set_fence(self, fence: Geofence) -> None:
        """Keep ``fence`` from now on instead of the world's, the obstacles as they are:
        the fence a ground station uploaded to the vehicle (offboard.daemon.fence_sync).
        The buffers grow when it has more faces; call between two steps."""
        planes, self.fence_margin = make_world((), fence).fence_arrays()
        self.fence = np.ascontiguousarray(planes, dtype=float)
        need = len(self.table) + len(self.fence)
        if need > self.capacity:
            self.capacity = need
            self.normals = np.zeros((need, 3))
            self.offsets = np.zeros(need)

    def at(self, p: np.ndarray) -> int:
        """The number of half-spaces for an agent at ``p`` (3,) (m), written into
        :attr:`normals` and :attr:`offsets`."""
        return int(world_planes(self.table, self.clearance, self.fence, self.fence_margin, p,
                                self.range_m, self.normals, self.offsets))

    def fence_planes_at(self, p: np.ndarray) -> int:
        """How many of :meth:`at`'s half-spaces for ``p`` are the fence's (they follow
        the obstacles'): its planes within range, by the test :func:`world_planes`
        makes, in the same operations (so the same answer)."""
        f, x = self.fence, np.asarray(p, dtype=float)
        near = f[:, 0] * x[0] + f[:, 1] * x[1] + f[:, 2] * x[2] - f[:, 3] < self.range_m
        return int(np.count_nonzero(near))
