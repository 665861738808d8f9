"""Virtual control → attitude/thrust setpoint, and a model of the inner loop (paper §2.2, §5.1).

``u = R[0,0,F]ᵀ/m − g e_z`` (§2.2) is turned into roll/pitch (yaw held) and thrust with
:func:`swarm_common.frames.accel_to_attitude` inside the tilt and thrust limits, then into
the MAVLink SET_ATTITUDE_TARGET payload: NED/FRD quaternion [w,x,y,z] and normalised
thrust, rounded to float32 as on the wire. :func:`decode_wire` reproduces what the
simulator makes of that payload (``euler_enu_from_quat_ned`` of the float32 quaternion,
``norm_to_thrust`` of the float32 thrust).

:class:`InnerLoopModel` predicts the virtual control the vehicle actually realises
(first-order attitude and thrust lags, §5.1, time constants from ``[vehicle]``); the DESO
uses it as its input u so that z3 estimates the disturbance, not the inner-loop lag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarm_common.frames import (
    accel_to_attitude,
    euler_enu_from_quat_ned,
    norm_to_thrust,
    thrust_to_norm,
)
from swarm_common.scenario import VehicleConfig


@dataclass
class Setpoint:
    """Attitude/thrust setpoint: as commanded and as decoded from the float32 wire form."""

    roll: float
    pitch: float
    yaw: float
    thrust_n: float
    q_ned: np.ndarray  # (4,) float32 [w, x, y, z]
    thrust_norm: np.float32


_S2 = math.sqrt(0.5)


def _qmul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_ned_fast(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Closed form of :func:`swarm_common.frames.quat_ned_from_euler_enu` (w ≥ 0).

    ``q_ned = q_T ⊗ q_zyx(roll, pitch, yaw) ⊗ q_D`` with T (ENU→NED) a half turn about
    (1,1,0)/√2 and D (FRD→FLU) a half turn about x; equal to the frames version to ~1e-16.
    """
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    q = (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )
    q = _qmul(_qmul((0.0, _S2, _S2, 0.0), q), (0.0, 1.0, 0.0, 0.0))
    if q[0] < 0:
        q = (-q[0], -q[1], -q[2], -q[3])
    return np.array(q)


def decode_wire(q_ned: np.ndarray, thrust_norm: float, thrust_max_n: float) -> tuple[float, ...]:
    """(roll, pitch, yaw, F) the simulator derives from a float32 wire setpoint."""
    q = np.asarray(q_ned, dtype=np.float32)
    roll, pitch, yaw = euler_enu_from_quat_ned(q)
    return roll, pitch, yaw, norm_to_thrust(float(np.float32(thrust_norm)), thrust_max_n)


def setpoint_from_accel(
    u: np.ndarray, yaw: float, veh: VehicleConfig, decode: bool = False
) -> Setpoint:
    """u (ENU) → setpoint within ``[vehicle]`` tilt/thrust limits.

    Angles/thrust are the commanded values, or (``decode=True``) the values decoded from the
    float32 wire form (differ by ~1e-7; the agent's inner-loop model does not need them).
    """
    f_max = veh.thrust_max_n
    roll, pitch, yaw_c, f = accel_to_attitude(
        u, yaw, veh.gravity_mps2, veh.mass_kg, math.radians(veh.tilt_max_deg), f_max
    )
    q = quat_ned_fast(roll, pitch, yaw_c).astype(np.float32)
    tn = np.float32(thrust_to_norm(f, f_max))
    if decode:
        roll, pitch, yaw_c, f = decode_wire(q, float(tn), f_max)
    return Setpoint(roll, pitch, yaw_c, f, q, tn)


def accel_from_attitude(
    roll: float, pitch: float, yaw: float, thrust_n: float, mass: float, g: float
) -> np.ndarray:
    """Virtual control realised by an attitude/thrust: R e3 F/m − g e_z (ENU)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    k = thrust_n / mass
    return np.array(
        [(cy * sp * cr + sy * sr) * k, (sy * sp * cr - cy * sr) * k, cp * cr * k - g]
    )


class InnerLoopModel:
    """First-order attitude (τ_rp, τ_ψ) and thrust (τ_F) lags, exact per sub-step."""

    def __init__(self, veh: VehicleConfig, dt_sub: float) -> None:
        self.m = veh.mass_kg
        self.g = veh.gravity_mps2
        self.tilt = math.radians(veh.tilt_max_deg)
        self.f_max = veh.thrust_max_n
        self.a_rp = math.exp(-dt_sub / veh.tau_rollpitch_s)
        self.a_y = math.exp(-dt_sub / veh.tau_yaw_s)
        self.a_f = math.exp(-dt_sub / veh.tau_thrust_s)
        self.att = [0.0, 0.0, 0.0]
        self.f = self.m * self.g

    def run(self, sp: Setpoint, n_sub: int) -> np.ndarray:
        """Advance ``n_sub`` sub-steps under ``sp``; (n_sub, 3) realised u at each sub-step end."""
        lim = self.tilt
        rc = min(lim, max(-lim, sp.roll))
        pc = min(lim, max(-lim, sp.pitch))
        yc = sp.yaw
        fc = min(self.f_max, max(0.0, sp.thrust_n))
        rows = []
        r, p, y = self.att
        f = self.f
        m, g = self.m, self.g
        cos, sin = math.cos, math.sin
        for _ in range(n_sub):
            r = rc + (r - rc) * self.a_rp
            p = pc + (p - pc) * self.a_rp
            y = yc + (y - yc) * self.a_y
            f = fc + (f - fc) * self.a_f
            cr, sr, cp, sp_, cy, sy = cos(r), sin(r), cos(p), sin(p), cos(y), sin(y)
            k = f / m
            rows.append(((cy * sp_ * cr + sy * sr) * k, (sy * sp_ * cr - cy * sr) * k,
                         cp * cr * k - g))
        self.att = [r, p, y]
        self.f = f
        return np.array(rows)
