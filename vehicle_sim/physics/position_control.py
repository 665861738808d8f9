"""The vehicle's own position controller: position / velocity / acceleration -> attitude, thrust.

It flies what PX4's multicopter position controller flies: a :class:`PositionSetpoint`
(ENU, metres, NaN on an axis that is not controlled), from the AUTO modes
(:mod:`vehicle_sim.autopilot.nav_flight` turns a :class:`~vehicle_sim.autopilot.nav.NavTarget` into
one) or
from OFFBOARD position-target messages (:mod:`vehicle_sim.autopilot.setpoints`).

Per axis, as PX4 cascades it (``PositionControl``):

* position given: velocity reference ``v_ref = kp (p_sp − p) + v_ff`` (``v_ff`` = the
  velocity setpoint when also given, else 0);
* velocity given alone: ``v_ref = v_sp``;
* the horizontal ``v_ref`` is limited to :attr:`SpeedLimits.xy` (norm), the vertical one
  to ``[−down, up]``, each limit no higher than the controller's ceiling
  (:meth:`PositionController.set_ceiling`: PX4's ``MPC_XY_VEL_MAX``,
  ``MPC_Z_VEL_MAX_UP``, ``MPC_Z_VEL_MAX_DN``, whatever the mode asks);
* an axis with a velocity reference gets ``u = kd (v_ref − v) + ∫ ki (v_ref − v) dt``
  (integral clamped) plus the acceleration setpoint as feed-forward; an axis with an
  acceleration setpoint only gets that acceleration.

``u`` is the paper's virtual control (m/s², eq. 2.2: ``u = R[0,0,F]/m − g e_z``);
:func:`swarm_common.frames.accel_to_attitude` turns it into (roll, pitch, yaw, F) with
the tilt limit (``MPC_TILTMAX_AIR``). The thrust scale is PX4's hover feed-forward:
``F = F_max · MPC_THR_HOVER · |u + g e_z| / g``, i.e. the controller believes the mass is
``MPC_THR_HOVER · F_max / g``. With the physical hover thrust (m g / F_max, the
parameter's default) that is exact; a wrong ``MPC_THR_HOVER`` gives, as on PX4, a
vertical transient that the integrator removes.

Gains are the onboard hold controller's (:class:`vehicle_sim.physics.failsafe_controller.HoldGains`)
except the vertical integral, which is PX4's (``MPC_Z_VEL_I_ACC`` = 2 /s) and clamped
wide enough to absorb a hover-thrust error of ±30 % (:class:`PositionGains`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarm_common import frames
from vehicle_sim.physics.failsafe_controller import HoldGains

NAN3 = np.full(3, np.nan)


@dataclass
class PositionGains(HoldGains):
    """HoldGains plus the vertical integral (gain 1/s, clamp m/s²)."""

    ki_z: float = 2.0  # PX4 MPC_Z_VEL_I_ACC default
    i_max_z: float = 4.0


@dataclass(frozen=True)
class PositionSetpoint:
    """ENU position (m), velocity (m/s), acceleration (m/s²); NaN = that component is not
    controlled. ``yaw`` (ENU rad) or ``yaw_rate`` (rad/s), None = keep the current yaw."""

    pos: np.ndarray = field(default_factory=lambda: NAN3.copy())
    vel: np.ndarray = field(default_factory=lambda: NAN3.copy())
    acc: np.ndarray = field(default_factory=lambda: NAN3.copy())
    yaw: float | None = None
    yaw_rate: float | None = None


@dataclass(frozen=True)
class SpeedLimits:
    """Velocity-reference limits (m/s): horizontal norm, climb, descent (all > 0)."""

    xy: float
    up: float
    down: float


class PositionController:
    """One vehicle's cascaded position/velocity controller (see the module docstring)."""

    def __init__(
        self,
        gravity: float,
        thrust_max_n: float,
        tilt_max_rad: float,
        hover_norm: float,
        gains: PositionGains | None = None,
    ) -> None:
        self.gravity = float(gravity)
        self.thrust_max_n = float(thrust_max_n)
        self.tilt_max_rad = float(tilt_max_rad)
        self.hover_norm = float(hover_norm)
        self.gains = gains or PositionGains()
        self.integ = np.zeros(3)
        self.yaw_ref = 0.0
        self.ceiling: SpeedLimits | None = None

    def reset(self, yaw: float) -> None:
        """Forget the integral and hold ``yaw`` until a setpoint says otherwise."""
        self.integ = np.zeros(3)
        self.yaw_ref = float(yaw) if math.isfinite(yaw) else 0.0

    def set_limits(self, tilt_max_rad: float, hover_norm: float) -> None:
        """Tilt limit (rad) and hover thrust (normalised), from the parameters."""
        self.tilt_max_rad = float(tilt_max_rad)
        self.hover_norm = float(hover_norm)

    def set_ceiling(self, ceiling: SpeedLimits | None) -> None:
        """Speed ceilings (m/s) applied on top of every step's limits (None: none)."""
        self.ceiling = ceiling

    def velocity_reference(
        self, sp: PositionSetpoint, p: np.ndarray, lim: SpeedLimits
    ) -> np.ndarray:
        """Velocity reference per axis (NaN where neither position nor velocity is given)."""
        top = self.ceiling
        if top is not None:
            lim = SpeedLimits(min(lim.xy, top.xy), min(lim.up, top.up), min(lim.down, top.down))
        kp = np.array([self.gains.kp_xy, self.gains.kp_xy, self.gains.kp_z])
        has_pos = np.isfinite(sp.pos)
        ff = np.where(np.isfinite(sp.vel), sp.vel, 0.0)
        v_ref = np.where(has_pos, kp * (np.where(has_pos, sp.pos, 0.0) - p) + ff, sp.vel)
        xy = v_ref[:2]
        if np.all(np.isfinite(xy)):
            n = float(np.hypot(xy[0], xy[1]))
            if n > lim.xy:
                v_ref[:2] = xy * (lim.xy / n)
        if math.isfinite(v_ref[2]):
            v_ref[2] = min(lim.up, max(-lim.down, float(v_ref[2])))
        return v_ref

    def acceleration(
        self, sp: PositionSetpoint, p: np.ndarray, v: np.ndarray, lim: SpeedLimits, dt: float
    ) -> np.ndarray:
        """The virtual control u (m/s², ENU) for this step; updates the integral."""
        g = self.gains
        v_ref = self.velocity_reference(sp, p, lim)
        vel_ctl = np.isfinite(v_ref)
        ev = np.where(vel_ctl, v_ref - v, 0.0)
        kd = np.array([g.kd_xy, g.kd_xy, g.kd_z])
        if dt > 0:
            ki = np.array([g.ki, g.ki, g.ki_z])
            i_max = np.array([g.i_max, g.i_max, g.i_max_z])
            self.integ += ki * ev * dt
            np.clip(self.integ, -i_max, i_max, out=self.integ)
        self.integ[~vel_ctl] = 0.0
        acc_ff = np.where(np.isfinite(sp.acc), sp.acc, 0.0)
        u = np.where(vel_ctl, kd * ev + self.integ, 0.0) + acc_ff
        np.clip(u, -g.a_max, g.a_max, out=u)
        if not np.all(np.isfinite(u)):
            u = np.zeros(3)
            self.integ = np.zeros(3)
        return u

    def update(
        self, sp: PositionSetpoint, p: np.ndarray, v: np.ndarray, lim: SpeedLimits, dt: float
    ) -> tuple[float, float, float, float]:
        """One control step: setpoint and state (ENU) -> (roll, pitch, yaw, thrust N)."""
        p = np.asarray(p, dtype=float)
        v = np.asarray(v, dtype=float)
        if sp.yaw is not None and math.isfinite(sp.yaw):
            self.yaw_ref = float(sp.yaw)
        elif sp.yaw_rate is not None and math.isfinite(sp.yaw_rate):
            self.yaw_ref = math.remainder(self.yaw_ref + sp.yaw_rate * dt, math.tau)
        u = self.acceleration(sp, p, v, lim, dt)
        mass_model = self.hover_norm * self.thrust_max_n / self.gravity
        return frames.accel_to_attitude(
            u, self.yaw_ref, self.gravity, mass_model, self.tilt_max_rad, self.thrust_max_n
        )
