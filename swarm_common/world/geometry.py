"""The world's geometry, compiled: closest points of obstacles, the half-spaces an agent
keeps to this step, and the truth the verdict scores (docs/world.md).

An obstacle is one row of :attr:`swarm_common.world.config.World.table`: kind (0 sphere,
1 vertical cylinder, 2 box), centre (3), radius, z range (2), size (3), yaw (rad).

**Why half-spaces.** Every obstacle is convex. With q its surface point closest to the
agent at p and n the outward normal there, the obstacle lies in {x : nᵀ(x − q) ≤ 0}, so
an agent with nᵀp ≥ nᵀq + D keeps a distance ≥ D from it. The filter keeps that
half-space (re-taken from p each step) with the same rows as its ground barrier
(:mod:`offboard.safety.dcbf.world_rows`). A geofence, box or convex polygon prism, is an
intersection of half-spaces already (:meth:`swarm_common.world.config.Geofence.planes`).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel

SPHERE, CYLINDER, BOX = 0, 1, 2


@kernel
def closest_point(ob: np.ndarray, px: float, py: float, pz: float, out: np.ndarray) -> None:
    """Obstacle ``ob`` (one table row) seen from p = (px, py, pz) (m): into ``out`` (7,) the
    closest surface point q (m), the unit outward normal n there and the signed distance
    d (m; < 0 inside, then q and n are those of the nearest face). A point at a sphere's
    or cylinder's axis takes +z or +x as its normal."""
    kind = int(ob[0])
    cx, cy, cz = ob[1], ob[2], ob[3]
    if kind == SPHERE:
        r = ob[4]
        dx, dy, dz = px - cx, py - cy, pz - cz
        rho = math.sqrt(dx * dx + dy * dy + dz * dz)
        if rho > 0.0:
            nx, ny, nz = dx / rho, dy / rho, dz / rho
        else:
            nx, ny, nz = 0.0, 0.0, 1.0
        out[0], out[1], out[2] = cx + r * nx, cy + r * ny, cz + r * nz
        out[3], out[4], out[5] = nx, ny, nz
        out[6] = rho - r
        return
    if kind == CYLINDER:
        r, zlo, zhi = ob[4], ob[5], ob[6]
        dx, dy = px - cx, py - cy
        rho = math.sqrt(dx * dx + dy * dy)
        if rho > 0.0:
            ux, uy = dx / rho, dy / rho
        else:
            ux, uy = 1.0, 0.0
        if rho > r or pz < zlo or pz > zhi:  # outside
            qx, qy = (cx + r * ux, cy + r * uy) if rho > r else (px, py)
            qz = min(max(pz, zlo), zhi)
            ex, ey, ez = px - qx, py - qy, pz - qz
            d = math.sqrt(ex * ex + ey * ey + ez * ez)
            out[0], out[1], out[2] = qx, qy, qz
            out[3], out[4], out[5] = ex / d, ey / d, ez / d
            out[6] = d
            return
        side, below, above = r - rho, pz - zlo, zhi - pz
        if side <= below and side <= above:
            out[0], out[1], out[2] = cx + r * ux, cy + r * uy, pz
            out[3], out[4], out[5] = ux, uy, 0.0
            out[6] = -side
        elif below <= above:
            out[0], out[1], out[2] = px, py, zlo
            out[3], out[4], out[5] = 0.0, 0.0, -1.0
            out[6] = -below
        else:
            out[0], out[1], out[2] = px, py, zhi
            out[3], out[4], out[5] = 0.0, 0.0, 1.0
            out[6] = -above
        return
    # box: the point in the box's frame (turned by −yaw about z)
    c, s = math.cos(ob[10]), math.sin(ob[10])
    dx, dy, dz = px - cx, py - cy, pz - cz
    lx, ly, lz = c * dx + s * dy, -s * dx + c * dy, dz
    hx, hy, hz = 0.5 * ob[7], 0.5 * ob[8], 0.5 * ob[9]
    qx, qy, qz = min(max(lx, -hx), hx), min(max(ly, -hy), hy), min(max(lz, -hz), hz)
    ex, ey, ez = lx - qx, ly - qy, lz - qz
    d = math.sqrt(ex * ex + ey * ey + ez * ez)
    if d > 0.0:  # outside
        nx, ny, nz = ex / d, ey / d, ez / d
    else:  # inside: the nearest face
        gx, gy, gz = hx - abs(lx), hy - abs(ly), hz - abs(lz)
        nx, ny, nz = 0.0, 0.0, 0.0
        if gx <= gy and gx <= gz:
            nx = 1.0 if lx >= 0.0 else -1.0
            qx, d = nx * hx, -gx
        elif gy <= gz:
            ny = 1.0 if ly >= 0.0 else -1.0
            qy, d = ny * hy, -gy
        else:
            nz = 1.0 if lz >= 0.0 else -1.0
            qz, d = nz * hz, -gz
    out[0], out[1], out[2] = cx + c * qx - s * qy, cy + s * qx + c * qy, cz + qz
    out[3], out[4], out[5] = c * nx - s * ny, s * nx + c * ny, nz
    out[6] = d


@kernel
def world_planes(table: np.ndarray, clearance: np.ndarray, fence: np.ndarray,
                 fence_margin: float, p: np.ndarray, range_m: float,
                 normals: np.ndarray, offsets: np.ndarray) -> int:
    """The half-spaces nᵀx ≥ c that an agent at ``p`` (3,) keeps this step, written into
    ``normals`` (P,3) and ``offsets`` (P,) (room for K + F); returns their count. One per
    obstacle of ``table`` (K rows) whose surface is within ``range_m`` (m): n its outward
    normal at the closest point q, c = nᵀq + ``clearance[k]``; then one per plane
    [n, c] of ``fence`` (F,4) (the fence's inward half-spaces, F = 0 without one,
    :meth:`swarm_common.world.config.Geofence.planes`) with nᵀp − c < ``range_m``:
    that n, c + ``fence_margin``."""
    out = np.empty(7)
    m = 0
    for k in range(table.shape[0]):
        closest_point(table[k], p[0], p[1], p[2], out)
        if out[6] < range_m:
            normals[m, 0], normals[m, 1], normals[m, 2] = out[3], out[4], out[5]
            offsets[m] = out[3] * out[0] + out[4] * out[1] + out[5] * out[2] + clearance[k]
            m += 1
    for j in range(fence.shape[0]):
        nx, ny, nz, c = fence[j, 0], fence[j, 1], fence[j, 2], fence[j, 3]
        if nx * p[0] + ny * p[1] + nz * p[2] - c < range_m:
            normals[m, 0], normals[m, 1], normals[m, 2] = nx, ny, nz
            offsets[m] = c + fence_margin
            m += 1
    return m


@kernel
def obstacle_distances(table: np.ndarray, p: np.ndarray, v: np.ndarray,
                       dist: np.ndarray, rate: np.ndarray) -> None:
    """Signed distances (m) of every point of ``p`` (K,N,3) to every obstacle into ``dist``
    (K,N,O), and their rates nᵀv (m/s) with the velocities ``v`` (K,N,3) into ``rate``."""
    out = np.empty(7)
    for k in range(p.shape[0]):
        for i in range(p.shape[1]):
            for o in range(table.shape[0]):
                closest_point(table[o], p[k, i, 0], p[k, i, 1], p[k, i, 2], out)
                dist[k, i, o] = out[6]
                rate[k, i, o] = out[3] * v[k, i, 0] + out[4] * v[k, i, 1] + out[5] * v[k, i, 2]


def fence_margins(fence: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(…) how far (m) each point of ``p`` (…,3) is inside the fence of half-spaces
    ``fence`` (F,4) [n, c] (F ≥ 1): the smallest nᵀp − c, the distance to the nearest
    face from inside, < 0 outside."""
    return np.min(fence_distances(fence, p), axis=-1)


def fence_distances(fence: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(…, F) nᵀp − c (m) of each point of ``p`` (…,3) to each plane of ``fence`` (F,4)."""
    p = np.asarray(p, dtype=float)[..., None, :]
    return (p[..., 0] * fence[:, 0] + p[..., 1] * fence[:, 1] + p[..., 2] * fence[:, 2]
            - fence[:, 3])
