"""Pair distances and contacts of the swarm's vehicles (:mod:`.dynamics_kernel`'s step).

:func:`contacts_into` gives a physics step its pairs in contact, those entering contact
and the least pair distance: up to :data:`GRID_MIN` vehicles in one pass over every pair
(with the step's distance matrix), past it on a grid of cells (:func:`_grid_contacts`,
O(N log N), no N × N matrix of distances). Every distance is :func:`_pair_dist`'s, summed
as ``np.add.reduce`` does, so the two ways give the same bits
(``tests/unit/vehicle_sim/test_dynamics_kernel.py``). :func:`pair_distances_kernel` and
:func:`min_upper_kernel` are the distance matrix and its least pair.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.jit import kernel


@kernel
def _pair_dist(p: np.ndarray, i: int, j: int) -> float:
    """‖p_i − p_j‖ (m), summed as ``np.add.reduce``: (x² + y²) + z²; every distance of
    this module (the matrix, the contacts, the grid)."""
    dx = p[i, 0] - p[j, 0]
    dy = p[i, 1] - p[j, 1]
    dz = p[i, 2] - p[j, 2]
    return math.sqrt((dx * dx + dy * dy) + dz * dz)


@kernel
def pair_distances_kernel(p: np.ndarray) -> np.ndarray:
    """(N,N) distance matrix ‖p_i − p_j‖ (m) of positions p (N,3) (m)."""
    n = p.shape[0]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = _pair_dist(p, i, j)
    return out


@kernel
def min_upper_kernel(d: np.ndarray) -> float:
    """Minimum of the strict upper triangle of the (N,N) matrix ``d`` (nan if any is nan;
    +inf for N < 2)."""
    n = d.shape[0]
    m = np.inf
    for i in range(n):
        for j in range(i + 1, n):
            x = d[i, j]
            if x < m or x != x:
                m = x
                if x != x:
                    return m
    return m


# above this many vehicles a step without a distance matrix finds its close pairs on a grid
GRID_MIN = 64
# the grid's cell side: the least nearest-neighbour distance of GRID_SAMPLES vehicles plus
# GRID_SLACK_M (m), at least the collision radius
GRID_SAMPLES = 8
GRID_SLACK_M = 0.25
CONTACT_ROOM = 64  # the contact pairs the grid pass has room for at first, doubled on demand


@kernel
def contacts_into(p: np.ndarray, in_contact: np.ndarray, radius: float, dist_out: np.ndarray,
                  pairs_out: np.ndarray, count: np.ndarray) -> tuple[int, float]:
    """The contacts (distance < ``radius``, m, i ≠ j) of ``p`` (N,3) into ``in_contact``
    (N,N) bool and the minimum pair distance. The pairs entering contact (not in
    ``in_contact`` before) go to the first rows of ``pairs_out`` as (i, j), i < j, in row
    order. Returns their number and the minimum over the pairs i < j (the
    :func:`min_upper_kernel` of the distance matrix: nan if any is nan; +inf for N < 2).
    ``count`` (1,) int64: the pairs in contact before, then after.

    With ``dist_out`` (N,N): one pass over the pairs i < j that also writes
    :func:`pair_distances_kernel` of ``p`` into it, each distance computed once and written
    to both of its cells (the other order's differences are the exact negations, so the
    same bits). With ``dist_out`` of shape (0, 0) and N > :data:`GRID_MIN`:
    :func:`_grid_contacts`, O(N log N), the same contacts, pairs and minimum, bit for bit
    (each pair's distance in the same arithmetic), no matrix."""
    n = p.shape[0]
    if dist_out.shape[0] != n:
        done, n_new, m = _grid_contacts(p, in_contact, radius, pairs_out, count)
        if done:
            return n_new, m
    n_new = 0
    m = np.inf
    full = dist_out.shape[0] == n
    inside = 0
    for i in range(n):
        in_contact[i, i] = False
        if full:
            dist_out[i, i] = _pair_dist(p, i, i)  # 0, or nan
        for j in range(i + 1, n):
            d = _pair_dist(p, i, j)
            c = d < radius
            if c and not in_contact[i, j]:
                pairs_out[n_new, 0] = i
                pairs_out[n_new, 1] = j
                n_new += 1
            if c:
                inside += 1
            in_contact[i, j] = c
            in_contact[j, i] = c
            if full:
                dist_out[i, j] = d
                dist_out[j, i] = d
            if m == m and (d < m or d != d):  # the first nan stays (min_upper_kernel)
                m = d
    count[0] = inside
    return n_new, m


@kernel
def _grid_contacts(p: np.ndarray, in_contact: np.ndarray, radius: float, pairs_out: np.ndarray,
                   count: np.ndarray) -> tuple[bool, int, float]:
    """:func:`contacts_into` without a distance matrix: (done, new pairs, minimum); done
    False (nothing written) where it cannot decide, and the caller passes over every pair.

    The vehicles are sorted into cubic cells of side h = max(radius, near + GRID_SLACK_M),
    ``near`` the least nearest-neighbour distance of GRID_SAMPLES vehicles, at least the
    minimum over all pairs. Every pair closer than h lies in the same or adjacent cells,
    the closest pair and every contact among them, so the minimum over those pairs is the
    minimum over all. Not done for N ≤ GRID_MIN, a coordinate that is not finite, or cells
    too many to number."""
    n = p.shape[0]
    if n <= GRID_MIN:
        return False, 0, np.inf
    lo = np.empty(3)
    hi = np.empty(3)
    for k in range(3):
        lo[k] = np.inf
        hi[k] = -np.inf
    for i in range(n):
        for k in range(3):
            x = p[i, k]
            if not math.isfinite(x):
                return False, 0, np.inf
            lo[k] = min(lo[k], x)
            hi[k] = max(hi[k], x)
    # the cell side: the nearest neighbour of any vehicle bounds the minimum above, so the
    # least of GRID_SAMPLES vehicles' nearest (O(N) each) gives cells that hold the closest
    # pair; the slack keeps a cell from being smaller than the contacts need
    near = np.inf
    for s in range(GRID_SAMPLES):
        i = (s * n) // GRID_SAMPLES
        for j in range(n):
            if j != i:
                near = min(near, _pair_dist(p, i, j))
    h = max(radius, near + GRID_SLACK_M)
    dims = np.empty(3, dtype=np.int64)
    total = 1.0
    for k in range(3):
        dims[k] = int((hi[k] - lo[k]) / h) + 3
        total *= dims[k]
    if total > 4e18:
        return False, 0, np.inf
    keys = np.empty(n, dtype=np.int64)
    cell = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for k in range(3):
            cell[i, k] = int((p[i, k] - lo[k]) / h) + 1
        keys[i] = (cell[i, 0] * dims[1] + cell[i, 1]) * dims[2] + cell[i, 2]
    # the vehicles by cell: a table of each cell's first row when the cells are few (a
    # counting sort), else sorted keys searched by bisection
    dense = total <= 16 * n + 4096
    cells = int(total) + 1 if dense else 1
    start = np.zeros(cells, dtype=np.int64)
    if dense:
        for i in range(n):
            start[keys[i] + 1] += 1
        for q in range(1, cells):
            start[q] += start[q - 1]
        order = np.empty(n, dtype=np.int64)
        fill = start.copy()
        for i in range(n):
            order[fill[keys[i]]] = i
            fill[keys[i]] += 1
        sorted_keys = keys  # not read
    else:
        order = np.argsort(keys, kind="mergesort")
        sorted_keys = keys[order]
    # the pairs closer than ``radius``, in rooms doubled until they hold them all (the
    # scan itself reassigns no array: numba would count references on every pair)
    room = CONTACT_ROOM
    while True:
        cand_i = np.empty(room, dtype=np.int64)
        cand_j = np.empty(room, dtype=np.int64)
        k_c, m = _scan_cells(p, cell, dims, dense, start, order, sorted_keys, radius,
                             cand_i, cand_j)
        if k_c <= room:
            break
        room *= 2
    if not m < h:
        return False, 0, np.inf
    # the contacts now, in row order (i, then j)
    rank = np.argsort(cand_i[:k_c] * n + cand_j[:k_c], kind="mergesort")
    n_new = 0
    for q in range(k_c):
        i, j = cand_i[rank[q]], cand_j[rank[q]]
        if not in_contact[i, j]:
            pairs_out[n_new, 0] = i
            pairs_out[n_new, 1] = j
            n_new += 1
    if count[0] > 0:  # some pair was in contact: clear every flag (rare)
        for i in range(n):
            for j in range(n):
                in_contact[i, j] = False
    for q in range(k_c):
        i, j = cand_i[q], cand_j[q]
        in_contact[i, j] = True
        in_contact[j, i] = True
    count[0] = k_c
    return True, n_new, m


@kernel
def _scan_cells(p: np.ndarray, cell: np.ndarray, dims: np.ndarray, dense: bool,
                start: np.ndarray, order: np.ndarray, sorted_keys: np.ndarray, radius: float,
                cand_i: np.ndarray, cand_j: np.ndarray) -> tuple[int, float]:
    """:func:`_grid_contacts`' pass over the pairs of the same or adjacent cells: (the
    pairs closer than ``radius``, the least distance (m) over the pairs passed). The first
    of those pairs (i < j, in scan order) are written into ``cand_i``, ``cand_j`` while
    they have room; a count over their length means they had too little, and the caller
    passes again with more."""
    m = np.inf
    k_c = 0
    room = cand_i.shape[0]
    for i in range(p.shape[0]):
        for a in range(-1, 2):
            for b in range(-1, 2):
                # the three cells (x + a, y + b, z - 1 .. z + 1) are one run of the rows
                first = ((cell[i, 0] + a) * dims[1] + cell[i, 1] + b) * dims[2] + cell[i, 2] - 1
                if dense:
                    r, end = start[first], start[first + 3]
                else:
                    r = np.searchsorted(sorted_keys, first)
                    end = np.searchsorted(sorted_keys, first + 3)
                while r < end:
                    j = order[r]
                    r += 1
                    if j <= i:
                        continue
                    d = _pair_dist(p, i, j)
                    if d < m:
                        m = d
                    if d < radius:
                        if k_c < room:
                            cand_i[k_c] = i
                            cand_j[k_c] = j
                        k_c += 1
    return k_c, m
