"""Per-vehicle PX4-style protocol state machine (no sockets: unit-testable).

The server feeds it decoded MAVLink messages (:meth:`Vehicle.handle`), calls
:meth:`Vehicle.update` once per control step (offboard-loss failsafe, auto-disarm),
:meth:`Vehicle.command` to get the attitude/thrust command for the dynamics, and
:meth:`Vehicle.periodic` for the telemetry streams. Everything the vehicle wants to send
is appended to :attr:`Vehicle.outbox` as ``(message, dest)``; ``dest`` is ``None`` for
"every link, every peer" or ``(link_name, addr)`` for a reply to one requester.

Its state and the helpers that read it are :class:`vehicle_sim.autopilot.state.VehicleState`
(which it extends), its settings :class:`vehicle_sim.autopilot.config.AutopilotConfig`.
Modes (PX4 custom_mode = main << 16 | sub << 24): POSCTL (default; armed = position hold,
there are no sticks), ALTCTL, OFFBOARD, AUTO.TAKEOFF, AUTO.LOITER ("HOLD"), AUTO.MISSION,
AUTO.RTL and AUTO.LAND ("LAND"); their logic is :mod:`vehicle_sim.autopilot.modes`, the
setpoint messages are parsed in :mod:`vehicle_sim.autopilot.setpoints`. Offboard rules,
failsafe and lockstep: docs/conventions.md and docs/px4/modes.md. The messages it sends
are built in :mod:`vehicle_sim.autopilot.telemetry`, the commands it answers in
:mod:`vehicle_sim.services.command`.

Times: ``wall`` (monotonic seconds) drives the telemetry schedule; ``sim_t`` (seconds of
simulation time) drives everything about flight: offboard setpoint freshness and loss,
landing, time stamps (``time_boot_ms`` = sim time).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as M

from swarm_common import px4
from swarm_common.enums import VehicleMode
from vehicle_sim.autopilot import audit, modes, nav_flight, setpoint_input, telemetry
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.setpoints import SetpointKind
from vehicle_sim.autopilot.state import Dest, VehicleState
from vehicle_sim.autopilot.streams import PeerStreams
from vehicle_sim.physics.position_control import PositionSetpoint, SpeedLimits
from vehicle_sim.services import command as commands
from vehicle_sim.services.command import Command
from vehicle_sim.services.mission import MissionService
from vehicle_sim.services.registry import attach_services

MSG_ODOMETRY = M.MAVLINK_MSG_ID_ODOMETRY
COMPONENT_AUTOPILOT = M.MAV_COMP_ID_AUTOPILOT1


class Vehicle(VehicleState):
    """One simulated PX4 vehicle, reading its state from ``dyn`` row ``idx``: the
    autopilot's state (:class:`~vehicle_sim.autopilot.state.VehicleState`), its MAVLink
    message handlers and its services."""

    mission: MissionService  # attached by vehicle_sim.services.registry

    def __init__(
        self, agent_id: int, idx: int, dyn: Any, cfg: AutopilotConfig | None = None
    ) -> None:
        super().__init__(agent_id, idx, dyn, cfg)
        # per-link default sets: onboard on the API link, PX4's normal set on the GCS link
        self.streams = PeerStreams(self.cfg.rates, self.cfg.odometry_hz, self.cfg.gcs_rates)
        self._handlers: dict[int, Callable[[Any, Dest, float, float], None]] = {
            M.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET: self._on_setpoint,
            M.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED: self._on_position_target,
            M.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT: self._on_position_target,
            M.MAVLINK_MSG_ID_COMMAND_LONG: self._on_command_long,
            M.MAVLINK_MSG_ID_COMMAND_INT: self._on_command_int,
            M.MAVLINK_MSG_ID_SET_MODE: self._on_set_mode,
            M.MAVLINK_MSG_ID_TIMESYNC: self._on_timesync,
        }
        self.services = attach_services(self)
        for svc in self.services:
            self._handlers.update(svc.handlers())
            self.command_handlers.update(svc.command_handlers())

    def _ack(self, src: Dest, cmd: int, result: int, m: Any = None) -> None:
        ts = m.get_srcSystem() if m is not None else 0
        tc = m.get_srcComponent() if m is not None else 0
        self.outbox.append((M.MAVLink_command_ack_message(cmd, result, 0, 0, ts, tc), src))

    # ==================================================================================
    # modes and arming (vehicle_sim.autopilot.modes)
    def request_mode(self, main: int, sub: int, sim_t: float) -> int:
        """Switch on a PX4 (main, sub) custom mode. Returns a MAV_RESULT."""
        return modes.request_mode(self, main, sub, sim_t)

    def arm(self, sim_t: float) -> int:
        return modes.arm(self, sim_t)

    def disarm(self, force: bool, why: str = "") -> int:
        return modes.disarm(self, force, why)

    def terminate(self) -> int:
        return modes.terminate(self)

    # ==================================================================================
    # message handling
    def handle(self, m: Any, src: Dest = None, wall: float = 0.0, sim_t: float = 0.0) -> None:
        """Process one decoded message received on ``src`` = (link_name, addr)."""
        tgt = getattr(m, "target_system", 0)
        if tgt not in (0, self.id):
            self.ctr.commands_foreign += 1
            return
        handler = self._handlers.get(m.get_msgId())
        if handler is not None:  # HEARTBEAT and everything else from a GCS: nothing to do
            handler(m, src, wall, sim_t)

    def _for_autopilot(self, m: Any) -> bool:
        """A command for component 0 (broadcast) or ours; else counted as foreign."""
        if getattr(m, "target_component", 0) in (0, COMPONENT_AUTOPILOT):
            return True
        self.ctr.commands_foreign += 1
        return False

    def _on_command_long(self, m: Any, src: Dest, wall: float, sim_t: float) -> None:
        if self._for_autopilot(m):
            p = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
            self._on_command(m, src, Command(m.command, p, wall, sim_t, src))

    def _on_command_int(self, m: Any, src: Dest, wall: float, sim_t: float) -> None:
        if self._for_autopilot(m):
            p = (m.param1, m.param2, m.param3, m.param4, m.x * 1e-7, m.y * 1e-7, m.z)
            self._on_command(m, src, Command(m.command, p, wall, sim_t, src, int(m.frame)))

    def _on_set_mode(self, m: Any, src: Dest, wall: float, sim_t: float) -> None:
        if m.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            res = self.request_mode(*px4.split_mode(m.custom_mode), sim_t)
        else:
            res = M.MAV_RESULT_UNSUPPORTED
        audit.record(self, m, src, sim_t, "SET_MODE", [m.base_mode, m.custom_mode],
                     audit.enum_name("MAV_RESULT", res), res == M.MAV_RESULT_ACCEPTED)
        self._ack(src, M.MAV_CMD_DO_SET_MODE, res, m)

    def _on_timesync(self, m: Any, src: Dest, wall: float, sim_t: float) -> None:
        if m.tc1 == 0:  # a request: answer with our (simulation) time in ns
            self.outbox.append((M.MAVLink_timesync_message(int(round(sim_t * 1e9)), m.ts1), src))

    def _on_command(self, m: Any, src: Dest, c: Command) -> None:
        self.ctr.commands += 1
        if getattr(m, "_restricted", False) and c.cmd not in commands.TELEMETRY_COMMANDS:
            self.ctr.commands_unsigned_refused += 1  # unsigned link: telemetry requests only
            audit.record_command(self, m, src, c.sim_t, c.cmd, c.p, M.MAV_RESULT_DENIED,
                                 "unsigned link: telemetry requests only")
            self._ack(src, c.cmd, M.MAV_RESULT_DENIED, m)
            return
        res, reply = commands.execute(self, c)
        audit.record_command(self, m, src, c.sim_t, c.cmd, c.p, res)
        if res == M.MAV_RESULT_UNSUPPORTED:
            self.ctr.commands_unsupported += 1
        self._ack(src, c.cmd, res, m)
        if reply is not None:
            self.outbox.append((reply, src))

    def _on_setpoint(self, m: Any, src: Dest, wall: float, sim_t: float) -> None:
        setpoint_input.on_attitude_target(self, m, sim_t)

    def _on_position_target(self, m: Any, src: Dest, wall: float, sim_t: float) -> None:
        setpoint_input.on_position_target(self, m, sim_t)

    # ==================================================================================
    # per control step
    def update(self, sim_t: float) -> None:
        """Services, offboard-loss failsafe, AUTO-mode progress and auto-disarm after
        landing (call once per step, before :meth:`command`)."""
        for svc in self.services:
            svc.update(sim_t)
        modes.offboard_loss(self, sim_t)
        modes.advance_auto(self, sim_t)
        if self.armed:
            modes.auto_disarm(self, sim_t)

    def command(self, dt: float) -> tuple[float, float, float, float]:
        """(roll, pitch, yaw, thrust N) to apply for the next control step."""
        i = self.idx
        if not self.armed:
            # motors off once it has flown; before that, hover thrust on the spawn fixture
            thrust = 0.0 if (self.ever_armed or self.terminated) else float(self.dyn.hold_thrust())
            return 0.0, 0.0, self.yaw(), thrust
        if self.mode == VehicleMode.OFFBOARD and not self.failsafe:
            if self.sp_kind == SetpointKind.ATTITUDE:
                r, pch, y = self.sp_att
                return float(r), float(pch), float(y), float(self.sp_thrust)
            return self._fly(self.sp_traj, nav_flight.OFFBOARD_LIMITS, dt)
        if self.nav is not None:
            sp, lim = nav_flight.nav_setpoint(self.nav, self.params, self.speed_override)
            return self._fly(sp, lim, dt)
        return self.fs.update(self.dyn.p[i], self.dyn.v[i], dt)

    def _fly(
        self, sp: PositionSetpoint, lim: SpeedLimits, dt: float
    ) -> tuple[float, float, float, float]:
        """The position controller with this step's MPC_TILTMAX_AIR and MPC_THR_HOVER."""
        tilt = min(math.radians(self.params.get("MPC_TILTMAX_AIR")), float(self.dyn.tilt_max))
        self.pc.set_limits(tilt, float(self.params.get("MPC_THR_HOVER")))
        return self.pc.update(sp, self.dyn.p[self.idx], self.dyn.v[self.idx], lim, dt)

    # ==================================================================================
    # telemetry (vehicle_sim.autopilot.telemetry builds the messages)
    def landed_state(self) -> int:
        return telemetry.landed_state(self)

    def heartbeat(self) -> M.MAVLink_heartbeat_message:
        return telemetry.heartbeat(self)

    def odometry(self, sim_t: float) -> M.MAVLink_odometry_message:
        return telemetry.odometry(self, sim_t)

    def build(self, mid: int, sim_t: float) -> M.MAVLink_message | None:
        """Build message ``mid`` from the current state (None if not supported)."""
        return telemetry.build(self, mid, sim_t)

    def periodic(
        self, wall: float, sim_t: float, skip: tuple[int, ...] = (), live: Any = None,
        heartbeat_only: bool = False,
    ) -> None:
        """Queue every stream whose interval has elapsed on the wall clock (to
        :attr:`stream_out`, as ``(message, (link, addr or None))``: None = every
        destination on the link's default schedule); ``live``: the peers still there
        (others lose their rates); ``heartbeat_only``: nobody takes a default schedule but
        its HEARTBEAT (``--default-streams on-contact``), so nothing else of it is built.
        A message due for several destinations in one call is built once."""
        if live is not None:
            self.streams.forget(live)
        built: dict[int, M.MAVLink_message | None] = {}
        for key, mid in self.streams.due(wall, skip):
            if heartbeat_only and key[1] is None and mid != M.MAVLINK_MSG_ID_HEARTBEAT:
                continue
            if mid not in built:
                built[mid] = telemetry.build(self, mid, sim_t)
            msg = built[mid]
            if msg is not None:
                self.stream_out.append((msg, key))

    def encoder(self, link: str = "api") -> M.MAVLink:
        """The encoder of one link: its own sequence counter, as PX4 keeps one per MAVLink
        instance (a client's loss count, e.g. pymavlink's ``mavloss``, sees every frame of
        its link in order), and its own signing stream (:meth:`sign_links`)."""
        enc = self.encs.get(link)
        if enc is None:
            enc = M.MAVLink(None, srcSystem=self.id, srcComponent=COMPONENT_AUTOPILOT)
            self.encs[link] = enc
        return enc

    def sign_links(self, key: bytes, links: tuple[str, ...], setup: Any) -> None:
        """Sign every link's frames with ``key``, link ``i`` with signing link id ``i``
        (``setup``: :func:`swarm_common.signing.setup_signing`)."""
        for i, name in enumerate(links):
            setup(self.encoder(name), key, i)

    def pack(self, msg: M.MAVLink_message, link: str = "api") -> bytes:
        """Encode for ``link`` with that link's sequence counter (sysid = agent id,
        compid 1)."""
        enc = self.encoder(link)
        buf = msg.pack(enc)
        enc.seq = (enc.seq + 1) % 256
        return buf
