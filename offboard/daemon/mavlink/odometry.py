"""The vehicle's ODOMETRY as the daemon keeps it, and the checks that admit one.

Entry points: :class:`Odometry` (the latest accepted reading, NED as on the wire) and
:func:`read_odometry`, which admits a decoded ODOMETRY only when its numbers are finite and
in range (:func:`~offboard.daemon.link_guard.odometry_fields_ok`) and its stamp moves
forward by a plausible amount (:class:`~offboard.daemon.link_guard.StampGuard`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from offboard.daemon.link_guard import StampGuard, odometry_fields_ok


@dataclass
class Odometry:
    """The latest ODOMETRY of the vehicle (NED, as on the wire): position (m), attitude
    quaternion (w, x, y, z, FRD -> NED) and body FRD velocity (m/s)."""

    time_usec: int
    x: float
    y: float
    z: float
    received: float
    q: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    v_body: tuple[float, float, float] = (0.0, 0.0, 0.0)


def read_odometry(msg: Any, stamps: StampGuard, now: float) -> Odometry | str:
    """The :class:`Odometry` of a decoded ODOMETRY ``msg`` received at ``now`` (s,
    monotonic), or why it is dropped ("duplicate stamp" among the reasons)."""
    q = tuple(map(float, msg.q))
    pos = (float(msg.x), float(msg.y), float(msg.z))
    vel = (float(msg.vx), float(msg.vy), float(msg.vz))
    why = odometry_fields_ok(pos, q, vel)
    if why is None:
        why = stamps.check(int(msg.time_usec), now)
    if why is not None:
        return why
    return Odometry(int(msg.time_usec), pos[0], pos[1], pos[2], now, (q[0], q[1], q[2], q[3]), vel)
