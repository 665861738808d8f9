"""What crosses a wire in a run, rounded as the wire rounds it, for the in-process runner.

Everything that would cross a wire is rounded to float32 (:func:`f32`): the truth, each
setpoint's quaternion and normalised thrust (decoded as the simulator decodes them:
:func:`wire_to_command`, for all agents at once :func:`wire_to_commands`) and the
agents' estimates (:func:`round_estimate`, all agents' as one :func:`published_batch`), so
a distributed run can reproduce an in-process one bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from offboard.estimation.peer_table import ROW, EstimateBatch
from offboard.records import NeighbourEstimate
from swarm_common.frames import euler_enu_from_quats_ned


def f32(x: np.ndarray | float) -> np.ndarray:
    """Round to float32 and back to float64: the value after one trip over the wire.

    Use it on every value that crosses a process boundary (truth p/v, setpoint quaternion
    and thrust_norm, neighbour estimates) in both the in-process and the distributed run.
    """
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def wire_to_command(
    q_ned: np.ndarray, thrust_norm: float | np.floating[Any], thrust_max_n: float
) -> tuple[float, float, float, float]:
    """SET_ATTITUDE_TARGET payload → (roll, pitch, yaw, F) exactly as the simulator does it.

    ``roll, pitch, yaw = euler_enu_from_quat_ned(float32 q)``; ``F = norm_to_thrust(float32
    thrust_norm)``. The simulator's MAVLink side must call this same function.
    """
    roll, pitch, yaw, f = wire_to_commands(
        np.asarray(q_ned, dtype=np.float32).reshape(1, 4),
        np.asarray([thrust_norm], dtype=np.float32), thrust_max_n,
    )
    return float(roll[0]), float(pitch[0]), float(yaw[0]), float(f[0])


def wire_to_commands(
    q_ned: np.ndarray, thrust_norm: np.ndarray, thrust_max_n: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`wire_to_command` of every agent at once: (N,4) float32 quaternions and (N,)
    float32 normalised thrusts → (N,) roll, pitch, yaw (rad), F (N):
    ``euler_enu_from_quat_ned`` of each float32 quaternion (one compiled call) and each
    float32 thrust times F_max (``norm_to_thrust``), as the simulator decodes them."""
    att = euler_enu_from_quats_ned(np.asarray(q_ned, dtype=np.float32))
    f = np.asarray(thrust_norm, dtype=np.float32).astype(np.float64) * thrust_max_n
    return att[:, 0], att[:, 1], att[:, 2], f


def round_estimates(ests: list[NeighbourEstimate]) -> list[NeighbourEstimate]:
    """:func:`round_estimate` of each of ``ests``: the four vectors of all of them rounded
    in one array (the same float32 value per element)."""
    x = _rounded_rows(ests)
    return [NeighbourEstimate(e.id, e.t, r[0:3], r[3:6], r[6:9], r[9:], e.is_leader,
                              e.cooperative)
            for e, r in zip(ests, x, strict=True)]


def round_estimate(e: NeighbourEstimate) -> NeighbourEstimate:
    """A published estimate as the receivers see it (float32 vectors; t kept exact)."""
    return round_estimates([e])[0]


def _rounded_rows(ests: list[NeighbourEstimate]) -> np.ndarray:
    """(len(ests), ROW) [z1, z2, z3, ξ] of each estimate, float32-rounded."""
    x = f32(np.concatenate([v for e in ests for v in (e.z1, e.z2, e.z3, e.xi)]))
    return x.reshape(len(ests), ROW)


def published_batch(ests: list[NeighbourEstimate]) -> EstimateBatch:
    """The estimates of all agents (scenario order) as every receiver sees them: one
    :class:`~offboard.estimation.peer_table.EstimateBatch`, rows as :func:`round_estimates` rounds
    them (t exact). Each row keeps its estimate's ``cooperative`` flag, as the wire does
    (offboard.daemon.wire_convert.put_row): a non-cooperative follower's estimates say so
    from its initial one on, and the others' full shares against it (offboard.agent.shares)
    start at the same step in both runs."""
    return EstimateBatch(
        np.array([e.t for e in ests], dtype=np.float64), _rounded_rows(ests),
        np.array([e.is_leader for e in ests], dtype=np.bool_),
        np.array([e.cooperative for e in ests], dtype=np.bool_),
    )
