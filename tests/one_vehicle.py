"""One simulated vehicle of ground8 (on its pad at z = 0) without sockets, stepped as the
server steps it: the vehicle's update, its command, physics_hz / control_hz dynamics steps.
Shared by the unit tests of the simulator's position control, AUTO modes and PX4
parameters (tests/unit/vehicle_sim/)."""

from __future__ import annotations

import math

import numpy as np
from conftest import ROOT
from pymavlink.dialects.v20 import common as M

from swarm_common.enums import VehicleMode
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics import geo
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.command import Command, execute
from vehicle_sim.vehicle import Vehicle

GROUND8 = ROOT / "scenarios" / "ground8.toml"
NAN = math.nan


class OneVehicle:
    """Vehicle 1 of ground8 on held dynamics; after every control step ``vel`` and ``pos``
    hold its velocity and position (ENU) and ``modes`` its mode."""

    def __init__(self) -> None:
        sc = load_scenario(GROUND8)
        self.dyn = SwarmDynamics(sc, held=True)
        self.v = Vehicle(1, 0, self.dyn, AutopilotConfig())
        self.dt = 1.0 / sc.run.control_hz
        self.sub = sc.substeps_per_control
        self.t = 0.0
        self.vel: list[np.ndarray] = []
        self.pos: list[np.ndarray] = []
        self.modes: list[VehicleMode] = []

    def step(self, seconds: float) -> None:
        v = self.v
        for _ in range(int(round(seconds / self.dt))):
            v.update(self.t)
            if v.release_requested:
                self.dyn.release(v.idx)
                v.release_requested = False
            self.dyn.set_command(v.idx, *v.command(self.dt))
            for _ in range(self.sub):
                self.dyn.step()
            self.t += self.dt
            self.vel.append(self.dyn.v[0].copy())
            self.pos.append(self.dyn.p[0].copy())
            self.modes.append(v.mode)

    def run(self, cmd: int, *p: float, frame: int = M.MAV_FRAME_GLOBAL) -> int:
        """The MAV_RESULT of command ``cmd`` with params ``p`` (the rest NaN)."""
        params = (*p, *(NAN,) * (7 - len(p)))
        return execute(self.v, Command(cmd, params, 0.0, self.t, None, frame))[0]

    def goto(self, north: float, east: float, up: float) -> int:
        """DO_REPOSITION to ENU (east, north, up) from the scenario origin (relative alt)."""
        lat_e7, lon_e7 = geo.latlon_e7(self.v.cfg, np.array([north, east, 0.0]))
        return self.run(M.MAV_CMD_DO_REPOSITION, -1, 1, 0, NAN, lat_e7 * 1e-7, lon_e7 * 1e-7,
                        up, frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)  # fmt: skip

    def trace(self) -> np.ndarray:
        """The velocities since the last call, one row per control step."""
        out = np.array(self.vel)
        self.vel.clear()
        return out

    @property
    def p(self) -> np.ndarray:
        return self.dyn.p[0].copy()
