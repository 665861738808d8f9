"""Onboard position-hold / land controller (HOLD, LAND, failsafe, armed POSCTL).

A PID on position and velocity in the ENU world frame produces the paper's virtual
control ``u`` (m/s²), which :func:`swarm_common.frames.accel_to_attitude` turns into
(roll, pitch, yaw, thrust) with the vehicle's tilt and thrust limits. Yaw is held at the
value it had when the controller was engaged.

* hold: track ``p_ref`` with zero velocity.
* land: track the horizontal ``p_ref`` and descend at ``land_speed`` (m/s) until the
  ground; PX4's MPC_LAND_SPEED default is 0.7 m/s. The caller disarms once landed.

The integral term (clamped) removes the steady offset the lumped disturbance (bias,
ground effect) would otherwise leave.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarm_common import frames
from swarm_common.enums import FailsafeAction


@dataclass
class HoldGains:
    kp_xy: float = 1.2
    kd_xy: float = 1.8
    kp_z: float = 2.0
    kd_z: float = 2.5
    ki: float = 0.4
    i_max: float = 2.0  # m/s² clamp of the integral term
    a_max: float = 6.0  # m/s² clamp of |u| per axis
    land_speed: float = 0.7  # m/s
    v_max_xy: float = 3.0  # m/s, limits the velocity reference in hold


@dataclass
class FailsafeController:
    mass: float
    gravity: float
    tilt_max_rad: float
    thrust_max_n: float
    gains: HoldGains = field(default_factory=HoldGains)

    def __post_init__(self) -> None:
        self.mode = FailsafeAction.HOLD
        self.p_ref = np.zeros(3)
        self.yaw_ref = 0.0
        self.integ = np.zeros(3)

    def engage(self, mode: FailsafeAction | str, p: np.ndarray, yaw: float) -> None:
        """Start holding (``FailsafeAction.HOLD``) or landing (``LAND``) from position ``p``
        (a plain ``"hold"``/``"land"`` works too; anything else raises ValueError)."""
        self.mode = FailsafeAction(mode)
        self.p_ref = np.array(p, dtype=float)
        self.yaw_ref = float(yaw) if math.isfinite(yaw) else 0.0
        self.integ = np.zeros(3)

    def update(self, p: np.ndarray, v: np.ndarray, dt: float) -> tuple[float, float, float, float]:
        """One control step: state (ENU) -> (roll, pitch, yaw, thrust N) command."""
        g = self.gains
        p = np.asarray(p, dtype=float)
        v = np.asarray(v, dtype=float)
        e = self.p_ref - p
        v_ref = np.zeros(3)
        # horizontal: position error -> bounded velocity reference
        v_xy = np.array([g.kp_xy * e[0], g.kp_xy * e[1]])
        n = float(np.hypot(*v_xy))
        if n > g.v_max_xy:
            v_xy *= g.v_max_xy / n
        v_ref[:2] = v_xy
        if self.mode == FailsafeAction.LAND:
            v_ref[2] = -g.land_speed
        else:
            v_ref[2] = max(-1.5, min(1.5, g.kp_z * e[2]))
        ev = v_ref - v
        u = np.array([g.kd_xy * ev[0], g.kd_xy * ev[1], g.kd_z * ev[2]])
        if dt > 0:
            self.integ += g.ki * ev * dt
            np.clip(self.integ, -g.i_max, g.i_max, out=self.integ)
        u += self.integ
        np.clip(u, -g.a_max, g.a_max, out=u)
        if not np.all(np.isfinite(u)):
            u = np.zeros(3)
            self.integ = np.zeros(3)
        return frames.accel_to_attitude(
            u, self.yaw_ref, self.gravity, self.mass, self.tilt_max_rad, self.thrust_max_n
        )
