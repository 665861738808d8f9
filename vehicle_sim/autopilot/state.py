"""The state of one simulated PX4 vehicle, and the helpers that read it.

:class:`VehicleState` owns what a vehicle knows: its mode, arming and failsafe flags,
AUTO-mode targets, offboard setpoints, lockstep bookkeeping, counters, outbox, stream
schedule, parameters and its own controllers; its position and attitude are row ``idx``
of the swarm dynamics ``dyn``. The functions of the autopilot room
(:mod:`.modes`, :mod:`.setpoint_input`, :mod:`.telemetry`) and the command service
(:mod:`vehicle_sim.services.command`) take one; :class:`vehicle_sim.vehicle.Vehicle`
extends it with the MAVLink message handlers and the services.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames, px4
from swarm_common.enums import FailsafeAction, VehicleMode
from vehicle_sim.autopilot.audit import AuditLog
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.nav import MissionControl, NavKind, NavTarget
from vehicle_sim.autopilot.nav_flight import RtlPlan
from vehicle_sim.autopilot.param_defaults import default_param_specs
from vehicle_sim.autopilot.params import ParamStore
from vehicle_sim.autopilot.setpoints import SetpointKind
from vehicle_sim.autopilot.streams import PeerStreams, StreamKey
from vehicle_sim.physics.failsafe_controller import FailsafeController
from vehicle_sim.physics.position_control import PositionController, PositionSetpoint

# (link name, peer address); peer None = every destination of that link
Dest = tuple[str, tuple[str, int] | None] | None
STATUSTEXT_LEN = 50
ODOM_STAMP_KEEP = 256  # ODOMETRY stamps whose send time is kept for the latency
LATENCY_KEEP = 200_000


@dataclass
class VehicleCounters:
    setpoints: int = 0
    setpoints_rejected: int = 0
    setpoints_stale: int = 0
    setpoints_unsupported: int = 0
    commands: int = 0
    commands_unsupported: int = 0
    commands_foreign: int = 0
    commands_unsigned_refused: int = 0  # flight commands on an unsigned link: DENIED
    lockstep_timeouts: int = 0
    failsafes: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


class VehicleState:
    """One simulated PX4 vehicle's state, reading its dynamics from ``dyn`` row ``idx``."""

    mission: MissionControl  # attached by vehicle_sim.services.registry

    def __init__(
        self, agent_id: int, idx: int, dyn: Any, cfg: AutopilotConfig | None = None
    ) -> None:
        self.id = int(agent_id)
        self.idx = int(idx)
        self.dyn = dyn
        self.cfg = cfg or AutopilotConfig()
        self.ctr = VehicleCounters()
        self.outbox: list[tuple[M.MAVLink_message, Dest]] = []
        # telemetry streams: None = every destination on the default schedule
        self.stream_out: list[tuple[M.MAVLink_message, StreamKey]] = []
        self.events: list[tuple[int, str]] = []  # (MAV_SEVERITY, line) for the server's log
        self.encs: dict[str, M.MAVLink] = {}  # per link (Vehicle.encoder())
        # commands received and their results (vehicle_sim.autopilot.audit; --stats-out)
        self.audit = AuditLog()
        # MAV_CMD -> handler(vehicle, command) of the services the vehicle attaches
        # (vehicle_sim.services.command.execute looks there first)
        self.command_handlers: dict[int, Any] = {}

        self.armed = False
        self.mode = VehicleMode.POSCTL
        self.failsafe = False  # in HOLD/LAND because the offboard stream was lost
        self.terminated = False
        self.ever_armed = False
        self.release_requested = False  # server: take it off the spawn fixture
        self.landed_since: float | None = None
        # AUTO modes (vehicle_sim.autopilot.modes): the target the position controller flies
        self.nav: NavTarget | None = None
        self.rtl: RtlPlan | None = None
        self.takeoff_alt: float | None = None  # NAV_TAKEOFF's altitude for the next entry
        self.speed_override: float | None = None  # DO_CHANGE_SPEED, m/s

        # setpoints (ENU/FLU, newtons)
        self.sp_att = np.array([0.0, 0.0, float(dyn.att[idx, 2])])
        self.sp_thrust = float(dyn.hold_thrust())
        self.sp_times: deque[float] = deque(maxlen=64)  # sim time of valid setpoints
        self.sp_kind = SetpointKind.ATTITUDE
        self.sp_traj = PositionSetpoint()
        self.last_sp_t: float | None = None
        self.last_sp_ms: int | None = None
        # lockstep
        self.expect_ms = 0  # the step a setpoint must echo (server sets it)
        self.answered_ms: int | None = None
        # setpoint-to-odometry latency: wall time each ODOMETRY stamp was built, and the
        # delay until the first valid setpoint echoing that stamp arrived (seconds)
        self.odom_wall: dict[int, float] = {}
        self.latency: deque[float] = deque(maxlen=LATENCY_KEEP)
        self.ever_answered = False
        self.consecutive_timeouts = 0
        self.wait_suspended = False

        self.fs = FailsafeController(dyn.mass, dyn.g, dyn.tilt_max, dyn.f_max)
        self.fs.engage(FailsafeAction.HOLD, dyn.p[idx], float(dyn.att[idx, 2]))
        self.home_enu = np.array([dyn.p[idx, 0], dyn.p[idx, 1], 0.0])
        self.home_ned = frames.enu_to_ned(self.home_enu)
        self.streams = PeerStreams(self.cfg.rates, self.cfg.odometry_hz)
        self.uid = self.cfg.uid_base | ((self.cfg.port_offset & 0xFFFF) << 8) | self.id
        self.params = ParamStore(default_param_specs(self.id, self.cfg, dyn))
        self.pc = PositionController(
            dyn.g, dyn.f_max, dyn.tilt_max, float(self.params.get("MPC_THR_HOVER"))
        )
        self.pc.reset(self.yaw())

    # ==================================================================================
    # state helpers
    @property
    def custom_mode(self) -> int:
        return px4.CUSTOM_MODE[self.mode]

    @property
    def active(self) -> bool:
        """Lockstep: the server waits for this vehicle's answer each step."""
        return self.armed and self.mode == VehicleMode.OFFBOARD and not self.failsafe

    def lockstep_should_wait(self) -> bool:
        return self.active and self.ever_answered and not self.wait_suspended

    def p(self) -> np.ndarray:
        return self.dyn.p[self.idx]

    def yaw(self) -> float:
        return float(self.dyn.att[self.idx, 2])

    def on_ground(self) -> bool:
        return bool(self.dyn.p[self.idx, 2] <= 1e-6)

    def event(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        """Log line for the server and STATUSTEXT to every link."""
        self.events.append((severity, f"vehicle {self.id}: {text}"))
        msg = M.MAVLink_statustext_message(severity, text[:STATUSTEXT_LEN].encode())
        self.outbox.append((msg, None))

    def setpoints_streaming(self, sim_t: float) -> bool:
        """>= ``setpoint_min_count`` valid setpoints within the last ``setpoint_window``."""
        lo = sim_t - self.cfg.setpoint_window
        n = sum(1 for t in self.sp_times if t >= lo)
        return n >= self.cfg.setpoint_min_count

    @property
    def landing(self) -> bool:
        """Armed and descending to land (EXTENDED_SYS_STATE: LANDING): AUTO.LAND, a
        mission LAND, RTL's last phase."""
        if not self.armed or self.mode == VehicleMode.OFFBOARD:
            return False
        return self.mode == VehicleMode.LAND or (
            self.nav is not None and self.nav.kind == NavKind.LAND
        )

    @property
    def taking_off(self) -> bool:
        """Armed and climbing to a take-off altitude (EXTENDED_SYS_STATE: TAKEOFF):
        AUTO.TAKEOFF, a mission TAKEOFF."""
        if not self.armed or self.mode == VehicleMode.OFFBOARD:
            return False
        return self.nav is not None and self.nav.kind == NavKind.TAKEOFF
