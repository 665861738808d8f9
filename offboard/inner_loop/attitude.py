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

from offboard.inner_loop.attitude_kernel import (
    accel_from_attitude_kernel,
    command_kernel,
    inner_loop_kernel,
    setpoint_kernel,
)
from swarm_common.fastnp import f64
from swarm_common.frames import euler_enu_from_quat_ned, norm_to_thrust
from swarm_common.jit import CallSite
from swarm_common.scenario.model import VehicleConfig


@dataclass(slots=True)
class Setpoint:
    """Attitude/thrust setpoint: as commanded and as decoded from the float32 wire form."""

    roll: float
    pitch: float
    yaw: float
    thrust_n: float
    q_ned: np.ndarray  # (4,) float32 [w, x, y, z]
    thrust_norm: np.float32


def decode_wire(q_ned: np.ndarray, thrust_norm: float, thrust_max_n: float) -> tuple[float, ...]:
    """(roll, pitch, yaw, F) the simulator derives from a float32 wire setpoint."""
    q = np.asarray(q_ned, dtype=np.float32)
    roll, pitch, yaw = euler_enu_from_quat_ned(q)
    return roll, pitch, yaw, norm_to_thrust(float(np.float32(thrust_norm)), thrust_max_n)


def _virtual_control(u: np.ndarray) -> np.ndarray:
    """``u`` as the (3,) float64 array the compiled conversions take; ValueError if it has
    another shape."""
    ua = f64(u)
    if ua.shape != (3,):
        raise ValueError(f"virtual control of shape {ua.shape}, not (3,)")
    return ua


def setpoint_from_accel(
    u: np.ndarray, yaw: float, veh: VehicleConfig, decode: bool = False
) -> Setpoint:
    """u (ENU) → setpoint within ``[vehicle]`` tilt/thrust limits.

    Angles/thrust are the commanded values, or (``decode=True``) the values decoded from the
    float32 wire form (differ by ~1e-7; the agent's inner-loop model does not need them).
    The conversion (:func:`swarm_common.frames.accel_to_attitude`, the quaternion of
    :func:`swarm_common.frames.quat_ned_from_euler_enu`,
    :func:`swarm_common.frames.thrust_to_norm`) is the compiled
    :func:`offboard.inner_loop.attitude_kernel.setpoint_kernel`.
    """
    ua = _virtual_control(u)
    f_max = veh.thrust_max_n
    roll, pitch, yaw_c, f, q, tn_f = setpoint_kernel(
        ua, float(yaw), float(veh.gravity_mps2), float(veh.mass_kg),
        math.radians(veh.tilt_max_deg), float(f_max),
    )
    tn = np.float32(tn_f)
    if decode:
        roll, pitch, yaw_c, f = decode_wire(q, float(tn), f_max)
    return Setpoint(roll, pitch, yaw_c, f, q, tn)


def accel_from_attitude(
    roll: float, pitch: float, yaw: float, thrust_n: float, mass: float, g: float
) -> np.ndarray:
    """Virtual control realised by an attitude/thrust: R e3 F/m − g e_z (ENU).

    Angles in rad, thrust in N, mass in kg, g in m/s²; the result (3,) in m/s² (compiled:
    :func:`offboard.inner_loop.attitude_kernel.accel_from_attitude_kernel`).
    """
    return accel_from_attitude_kernel(
        float(roll), float(pitch), float(yaw), float(thrust_n), float(mass), float(g)
    )


class InnerLoopModel:
    """First-order attitude (τ_rp, τ_ψ) and thrust (τ_F) lags, exact per sub-step."""

    def __init__(self, veh: VehicleConfig, dt_sub: float) -> None:
        self.m = float(veh.mass_kg)
        self.g = float(veh.gravity_mps2)
        self.tilt = math.radians(veh.tilt_max_deg)
        self.f_max = float(veh.thrust_max_n)
        self.a_rp = math.exp(-dt_sub / veh.tau_rollpitch_s)
        self.a_y = math.exp(-dt_sub / veh.tau_yaw_s)
        self.a_f = math.exp(-dt_sub / veh.tau_thrust_s)
        # [roll, pitch, yaw (rad), thrust (N)] realised: the state the kernels take
        self.state = np.array([0.0, 0.0, 0.0, self.m * self.g])
        # what :meth:`command` writes in place: its rows (one buffer per n_sub) and mean
        self._rows: dict[int, np.ndarray] = {}
        self._mean = np.zeros(3)
        self._command = CallSite(command_kernel)  # its arguments' types are fixed

    @property
    def att(self) -> list[float]:
        """Realised [roll, pitch, yaw] (rad)."""
        return [float(x) for x in self.state[:3]]

    @property
    def f(self) -> float:
        """Realised thrust (N)."""
        return float(self.state[3])

    def command(
        self, u: np.ndarray, yaw: float, n_sub: int, clip_tol: float
    ) -> tuple[Setpoint, np.ndarray, bool, np.ndarray]:
        """One control period of the virtual control ``u`` (3,) m/s² (ENU) at heading
        ``yaw`` (rad): its setpoint (:func:`setpoint_from_accel`), the ``n_sub`` realised
        rows of :meth:`run` under it, whether the setpoint realises an acceleration
        farther than ``clip_tol`` (m/s²) from u on some axis (tilt or thrust clipped), and
        the rows' mean (m/s²). One compiled call
        (:func:`offboard.inner_loop.attitude_kernel.command_kernel`), the same bits as those calls.

        The rows and the mean are this model's own buffers, rewritten by the next call:
        valid until then (each step reads them before its next command)."""
        ua = _virtual_control(u)
        rows = self._rows.get(n_sub)
        if rows is None:
            if not 1 <= n_sub <= 1000:
                raise ValueError(f"n_sub {n_sub} outside 1..1000")
            rows = self._rows[n_sub] = np.zeros((int(n_sub), 3))
        self.state = f64(self.state)
        q = np.empty(4, dtype=np.float32)  # new from Python: cheaper than one boxed
        roll, pitch, yaw_c, f, tn, clipped = self._command.call(
            ua, float(yaw), self.g, self.m, self.tilt, self.f_max, self.state, self.a_rp,
            self.a_y, self.a_f, float(clip_tol), rows, self._mean, q,
        )
        return Setpoint(roll, pitch, yaw_c, f, q, np.float32(tn)), rows, clipped, self._mean

    def run(self, sp: Setpoint, n_sub: int) -> np.ndarray:
        """Advance ``n_sub`` sub-steps under ``sp``; (n_sub, 3) realised u (m/s²) at each
        sub-step end. The command is clipped to the tilt and thrust limits and the
        sub-steps run in the compiled
        :func:`offboard.inner_loop.attitude_kernel.inner_loop_kernel`."""
        r, p, y, f0 = self.state.tolist()
        rows, r, p, y, f = inner_loop_kernel(
            r, p, y, f0, float(sp.roll), float(sp.pitch),
            float(sp.yaw), float(sp.thrust_n), self.tilt, self.f_max, self.a_rp, self.a_y,
            self.a_f, self.m, self.g, int(n_sub),
        )
        self.state = np.array([r, p, y, f])
        return rows
