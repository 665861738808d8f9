"""Which kinds of a dcbf QP's rows were active at its answer (the records' ``qp_active``
and ``qp_kinds``, docs/records.md): :func:`active_rows`, from where the step's rows came
(:meth:`offboard.safety.dcbf.filter.DcbfFilter.note_rows`, ``add_world_rows``,
``solve_limited``)."""

from __future__ import annotations

import numpy as np

from offboard.records import NO_ACTIVE, ActiveRows
from offboard.safety.dcbf.world_rows import WorldPlanes
from offboard.safety.rcbf.clf_rcbf import ACTIVE_TOL_MPS2, QPResult
from swarm_common.enums import QPRow

# the pair rows' scenario indices (sensed, then predicted) and whether the ground's two
# rows follow them
RowsOf = tuple[np.ndarray, np.ndarray, bool]
# the world's rows: its planes, their first row, their count and the agent's position
WorldOf = tuple[WorldPlanes, int, int, np.ndarray]
_INPUT, _CLF, _PAIR, _GROUND, _SPEED, _OBSTACLE, _FENCE = (
    int(QPRow.INPUT), int(QPRow.CLF), int(QPRow.PAIR), int(QPRow.GROUND), int(QPRow.SPEED),
    int(QPRow.OBSTACLE), int(QPRow.FENCE))
_FLAGS: dict[int, QPRow] = {}  # the QPRow of each combination of bits met so far


def active_rows(res: QPResult, rows_of: RowsOf, world_of: WorldOf | None,
                speed_from: int) -> ActiveRows:
    """The rows active at ``res``'s solution by kind: none unless the QP was solved. The
    rows lie as the filter wrote them: two per pair (the C1 rows, then the C2 rows), the
    ground's two, the world's two per plane (obstacles, then the fence) and, from row
    ``speed_from`` (< 0: none), the speed rows."""
    if res.tight is None:
        return NO_ACTIVE
    # the kinds as plain int bits (an IntFlag's | costs a microsecond), one QPRow at the end
    kinds, count = 0, len(res.tight) + res.tight_input
    if res.tight_input:
        kinds |= _INPUT
    if res.slack > ACTIVE_TOL_MPS2:
        kinds |= _CLF
        count += 1
    sensed, predicted, ground = rows_of
    n_s = len(sensed)
    m = n_s + len(predicted)
    pairs: list[int] = []
    n_obstacle = -1  # obstacle planes of the step's world rows, counted when needed
    for r in res.tight.tolist():
        if r < 2 * m:  # the (C1) rows of the pairs, then their (C2) rows
            i = r % m
            j = int(sensed[i]) if i < n_s else int(predicted[i - n_s])
            kinds |= _PAIR
            if j not in pairs:
                pairs.append(j)
        elif ground and r < 2 * m + 2:
            kinds |= _GROUND
        elif 0 <= speed_from <= r:  # the speed rows come last
            kinds |= _SPEED
        elif world_of is not None:  # two rows per plane: obstacles, then fence
            planes, first, n_planes, p = world_of
            if n_obstacle < 0:
                n_obstacle = n_planes - planes.fence_planes_at(p)
            kinds |= _OBSTACLE if (r - first) // 2 < n_obstacle else _FENCE
    flag = _FLAGS.get(kinds)
    if flag is None:
        flag = _FLAGS[kinds] = QPRow(kinds)
    return ActiveRows(count, flag, tuple(pairs))
