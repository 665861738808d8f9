"""Conversions between the agent's records and the Zenoh wire payloads, and the vehicle's
measured state from its ODOMETRY (NED/FRD in, ENU out through :mod:`swarm_common.frames`).
Pure functions, used by :mod:`offboard.daemon.core`."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from offboard.agent.factory import AgentOutput, NeighbourEstimate
from offboard.daemon.mavlink.odometry import Odometry
from offboard.estimation.peer_table import ROW, EstimateBatch
from offboard.estimation.reference import xi_p
from swarm_common import frames, wire
from swarm_common.enums import Role


def estimate_to_wire(e: NeighbourEstimate, step: int, zeta: np.ndarray | None) -> wire.Estimate:
    """An agent's published estimate as the Zenoh payload (made at control step ``step``)."""
    return wire.Estimate(
        cooperative=e.cooperative,
        id=e.id,
        step=step,
        t=float(e.t),
        role=Role.LEADER if e.is_leader else Role.FOLLOWER,
        z1=e.z1,
        z2=e.z2,
        z3=e.z3,
        xi=e.xi,
        zeta=np.zeros(6) if zeta is None else zeta,
    )


def estimates_from_wire(
    index_of: Mapping[int, int], n: int, received: Mapping[int, wire.Estimate]
) -> EstimateBatch:
    """Received payloads (by agent id) as the agent consumes them: one
    :class:`~offboard.estimation.peer_table.EstimateBatch` of the ``n`` agents by scenario index
    (``index_of``: id → index; ids outside it are left out), each row the payload's
    float32-rounded z1, z2, z3 and ξ (the decoded block's first ROW floats)."""
    b = EstimateBatch.empty(n)
    for aid, e in received.items():
        j = index_of.get(aid)
        if j is not None:
            put_row(b, j, e)
    return b


def put_row(b: EstimateBatch, j: int, e: wire.Estimate) -> None:
    """Row ``j`` of ``b`` from the received payload ``e``: its float32-rounded z1, z2, z3
    and ξ (the decoded block's first ROW floats), stamp, role and cooperation."""
    blk = e.block
    b.rows[j] = (blk[:ROW] if blk is not None and blk.shape[0] >= ROW
                 else np.concatenate([e.z1, e.z2, e.z3, e.xi]))
    b.t[j] = e.t
    b.leader[j] = e.role == Role.LEADER
    b.cooperative[j] = e.cooperative


def measured_state(odo: Odometry, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(position, velocity) ENU of the vehicle from its ODOMETRY (NED position, FRD->NED
    quaternion, body FRD velocity), the position carried ``dt`` s ahead at that velocity
    (an estimate is valid at t_k+1); None when the message's numbers are unusable."""
    q = np.asarray(odo.q, dtype=float)
    p_ned = np.array([odo.x, odo.y, odo.z], dtype=float)
    v_body = np.asarray(odo.v_body, dtype=float)
    if not (np.all(np.isfinite(p_ned)) and np.all(np.isfinite(v_body))
            and frames.valid_quaternion(q)):
        return None
    v = frames.ned_to_enu(frames.rotm_from_quat(q / np.linalg.norm(q)) @ v_body)
    return frames.ned_to_enu(p_ned) + v * dt, v


def status_to_wire(
    agent_id: int, step: int, t: float, out: AgentOutput, mode: str, comm_ok: bool
) -> wire.Status:
    st = out.status
    if not comm_ok:
        health = "predicting"
    elif st.fallbacks and st.qp_status.degraded:
        health = "qp-fallback"
    else:
        health = "ok"
    return wire.Status(
        id=agent_id,
        step=step,
        t=t,
        mode=mode,
        method=st.method,
        qp_status=st.qp_status,
        qp_solve_us=float(st.solve_us),
        h_min=float(st.h_min),
        lyap_v=float(st.V),
        est_health=health,
        fallbacks=int(st.fallbacks),
        u=np.asarray(out.u, dtype=float),
        z1=np.asarray(out.estimate.z1, dtype=float),
        p_des=np.asarray(xi_p(out.estimate.xi), dtype=float),
        comm_ok=comm_ok,
        lumped=np.asarray(out.lumped, dtype=float),
        input_clipped=bool(st.input_clipped),
        alarms=int(st.alarms),
        qp_active=int(st.active.count),
        qp_kinds=int(st.active.kinds),
        qp_slack=float(st.slack),
        qp_relax=float(st.violation),
        u_nom=np.asarray(st.u_nom, dtype=float),
        correction=float(st.correction),
    )
