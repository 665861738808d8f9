"""Per-vehicle PX4-style protocol state machine (no sockets: unit-testable).

The server feeds it decoded MAVLink messages (:meth:`Vehicle.handle`), calls
:meth:`Vehicle.update` once per control step (offboard-loss failsafe, auto-disarm),
:meth:`Vehicle.command` to get the attitude/thrust command for the dynamics, and
:meth:`Vehicle.periodic` for the telemetry streams. Everything the vehicle wants to send
is appended to :attr:`Vehicle.outbox` as ``(message, dest)``; ``dest`` is ``None`` for
"every link, every peer" or ``(link_name, addr)`` for a reply to one requester.

Modes (PX4 custom_mode = main << 16 | sub << 24): POSCTL (default; armed = position hold,
there are no sticks), OFFBOARD, AUTO.LOITER ("HOLD") and AUTO.LAND ("LAND").
Offboard rules, failsafe and lockstep: docs/conventions.md.

Times: ``wall`` (monotonic seconds) drives the telemetry schedule; ``sim_t`` (seconds of
simulation time) drives everything about flight: offboard setpoint freshness and loss,
landing, time stamps (``time_boot_ms`` = sim time).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from swarm_common import frames, px4
from vehicle_sim.failsafe_controller import FailsafeController

M = mavlink2

# -- PX4 modes (swarm_common/px4.py) --------------------------------------------------
PX4_MAIN_POSCTL = px4.MAIN_POSCTL
PX4_MAIN_AUTO = px4.MAIN_AUTO
PX4_MAIN_OFFBOARD = px4.MAIN_OFFBOARD
PX4_SUB_AUTO_LOITER = px4.SUB_AUTO_LOITER
PX4_SUB_AUTO_LAND = px4.SUB_AUTO_LAND
CUSTOM_MODE = px4.CUSTOM_MODE
FORCE_MAGIC = px4.FORCE_MAGIC

# MAVLink ids used below
MSG_HEARTBEAT = M.MAVLINK_MSG_ID_HEARTBEAT
MSG_SYS_STATUS = M.MAVLINK_MSG_ID_SYS_STATUS
MSG_GPS_RAW_INT = M.MAVLINK_MSG_ID_GPS_RAW_INT
MSG_ATTITUDE = M.MAVLINK_MSG_ID_ATTITUDE
MSG_ATTITUDE_QUATERNION = M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
MSG_LOCAL_POSITION_NED = M.MAVLINK_MSG_ID_LOCAL_POSITION_NED
MSG_GLOBAL_POSITION_INT = M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
MSG_ODOMETRY = M.MAVLINK_MSG_ID_ODOMETRY
MSG_HOME_POSITION = M.MAVLINK_MSG_ID_HOME_POSITION
MSG_EXTENDED_SYS_STATE = M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
MSG_AUTOPILOT_VERSION = M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
MSG_ATTITUDE_TARGET = M.MAVLINK_MSG_ID_ATTITUDE_TARGET

SENSORS = (
    M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | M.MAV_SYS_STATUS_SENSOR_3D_MAG
    | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | M.MAV_SYS_STATUS_SENSOR_GPS
    | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | M.MAV_SYS_STATUS_AHRS
    | M.MAV_SYS_STATUS_SENSOR_BATTERY
    | M.MAV_SYS_STATUS_PREARM_CHECK
)

TM_RATES_IGNORE = (
    M.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | M.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | M.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)
TM_THRUST_IGNORE = M.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE
TM_ATT_IGNORE = M.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE

EARTH_R = 6378137.0


def _finite(x: float | None, default: float | None = None) -> float | None:
    """A command parameter, or ``default`` when it is NaN/inf (MAVSDK sends NaN)."""
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return default
    return xf if math.isfinite(xf) else default


@dataclass
class VehicleConfig:
    offboard_timeout: float = 0.5  # s (sim time) without setpoint in OFFBOARD -> failsafe
    failsafe: str = "hold"  # "hold" | "land"
    odometry_hz: float = 50.0
    lockstep: bool = False
    setpoint_window: float = 0.5  # s: OFFBOARD needs >= setpoint_min_count in this window
    setpoint_min_count: int = 2
    land_disarm_delay: float = 1.0  # s on the ground in LAND before auto-disarm
    home_lat: float = 47.397742  # PX4 SITL default home (Zurich)
    home_lon: float = 8.545594
    home_alt: float = 488.0
    uid_base: int = 0x4253574152000000  # "BSWAR" + offset << 8 + id
    port_offset: int = 0
    # default stream rates (Hz); 0 = off. ODOMETRY uses odometry_hz.
    rates: dict[int, float] = field(
        default_factory=lambda: {
            MSG_HEARTBEAT: 1.0,
            MSG_SYS_STATUS: 1.0,
            MSG_EXTENDED_SYS_STATE: 1.0,
            MSG_GPS_RAW_INT: 1.0,
            MSG_ATTITUDE_QUATERNION: 20.0,
            MSG_ATTITUDE: 0.0,
            MSG_LOCAL_POSITION_NED: 20.0,
            MSG_GLOBAL_POSITION_INT: 5.0,
            MSG_HOME_POSITION: 0.2,
            MSG_ATTITUDE_TARGET: 0.0,
        }
    )


@dataclass
class VehicleCounters:
    setpoints: int = 0
    setpoints_rejected: int = 0
    setpoints_stale: int = 0
    setpoints_unsupported: int = 0
    commands: int = 0
    commands_unsupported: int = 0
    commands_foreign: int = 0
    lockstep_timeouts: int = 0
    failsafes: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


class Vehicle:
    """One simulated PX4 vehicle, reading its state from ``dyn`` row ``idx``."""

    def __init__(self, agent_id: int, idx: int, dyn, cfg: VehicleConfig | None = None) -> None:
        self.id = int(agent_id)
        self.idx = int(idx)
        self.dyn = dyn
        self.cfg = cfg or VehicleConfig()
        self.ctr = VehicleCounters()
        self.outbox: list[tuple[object, tuple[str, tuple[str, int]] | None]] = []
        self.events: list[str] = []  # human-readable log lines for the server's stderr
        self.enc = mavlink2.MAVLink(None, srcSystem=self.id, srcComponent=1)

        self.armed = False
        self.mode = "POSCTL"
        self.failsafe = False  # in HOLD/LAND because the offboard stream was lost
        self.terminated = False
        self.ever_armed = False
        self.release_requested = False  # server: take it off the spawn fixture
        self._landed_since: float | None = None

        # setpoints (ENU/FLU, newtons)
        self.sp_att = np.array([0.0, 0.0, float(dyn.att[idx, 2])])
        self.sp_thrust = float(dyn.hold_thrust())
        self.sp_times: deque[float] = deque(maxlen=64)  # sim time of valid setpoints
        self.last_sp_t: float | None = None
        self.last_sp_ms: int | None = None
        # lockstep
        self.expect_ms = 0  # the step a setpoint must echo (server sets it)
        self.answered_ms: int | None = None
        # setpoint-to-odometry latency: wall time each ODOMETRY stamp was built, and the
        # delay until the first valid setpoint echoing that stamp arrived (seconds)
        self.odom_wall: dict[int, float] = {}
        self.latency: deque[float] = deque(maxlen=200_000)
        self.ever_answered = False
        self.consecutive_timeouts = 0
        self.wait_suspended = False

        self.fs = FailsafeController(dyn.mass, dyn.g, dyn.tilt_max, dyn.f_max)
        self.fs.engage("hold", dyn.p[idx], float(dyn.att[idx, 2]))
        self.home_ned = frames.enu_to_ned(np.array([dyn.p[idx, 0], dyn.p[idx, 1], 0.0]))

        self.intervals: dict[int, float] = {}
        self._next_due: dict[int, float] = {}
        for mid, hz in self.cfg.rates.items():
            self.intervals[mid] = 1.0 / hz if hz > 0 else 0.0
        self.intervals[MSG_ODOMETRY] = 1.0 / self.cfg.odometry_hz if self.cfg.odometry_hz else 0
        self.uid = self.cfg.uid_base | ((self.cfg.port_offset & 0xFFFF) << 8) | self.id

    # ==================================================================================
    # state helpers
    @property
    def custom_mode(self) -> int:
        return CUSTOM_MODE[self.mode]

    @property
    def active(self) -> bool:
        """Lockstep: the server waits for this vehicle's answer each step."""
        return self.armed and self.mode == "OFFBOARD" and not self.failsafe

    def lockstep_should_wait(self) -> bool:
        return self.active and self.ever_answered and not self.wait_suspended

    def p(self) -> np.ndarray:
        return self.dyn.p[self.idx]

    def on_ground(self) -> bool:
        return bool(self.dyn.p[self.idx, 2] <= 1e-6)

    def event(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        self.events.append(f"vehicle {self.id}: {text}")
        self.outbox.append((M.MAVLink_statustext_message(severity, text[:50].encode()), None))

    def _reply(self, msg, src) -> None:
        self.outbox.append((msg, src))

    def _ack(self, src, cmd: int, result: int, m=None) -> None:
        ts = m.get_srcSystem() if m is not None else 0
        tc = m.get_srcComponent() if m is not None else 0
        self._reply(M.MAVLink_command_ack_message(cmd, result, 0, 0, ts, tc), src)

    def setpoints_streaming(self, sim_t: float) -> bool:
        """>= ``setpoint_min_count`` valid setpoints within the last ``setpoint_window``."""
        lo = sim_t - self.cfg.setpoint_window
        n = sum(1 for t in self.sp_times if t >= lo)
        return n >= self.cfg.setpoint_min_count

    # ==================================================================================
    # mode changes
    def _enter_mode(self, mode: str, sim_t: float, why: str = "") -> None:
        prev = self.mode
        if mode in ("HOLD", "POSCTL"):
            self.fs.engage("hold", self.p(), float(self.dyn.att[self.idx, 2]))
        elif mode == "LAND":
            self.fs.engage("land", self.p(), float(self.dyn.att[self.idx, 2]))
            self._landed_since = None
        self.mode = mode
        if prev != mode or why:
            self.event(f"mode {prev} -> {mode}{(' (' + why + ')') if why else ''}")

    def request_mode(self, main: int, sub: int, sim_t: float) -> int:
        """Switch on a PX4 (main, sub) custom mode. Returns a MAV_RESULT."""
        if main == PX4_MAIN_OFFBOARD:
            target = "OFFBOARD"
        elif main == PX4_MAIN_AUTO and sub == PX4_SUB_AUTO_LOITER:
            target = "HOLD"
        elif main == PX4_MAIN_AUTO and sub == PX4_SUB_AUTO_LAND:
            target = "LAND"
        elif main == PX4_MAIN_POSCTL:
            target = "POSCTL"
        else:
            return M.MAV_RESULT_UNSUPPORTED
        if self.terminated:
            return M.MAV_RESULT_DENIED
        if target == "OFFBOARD" and not self.setpoints_streaming(sim_t):
            self.event("OFFBOARD refused: no setpoint stream", M.MAV_SEVERITY_WARNING)
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        self.failsafe = False
        if target != self.mode:
            self._enter_mode(target, sim_t)
        return M.MAV_RESULT_ACCEPTED

    # ==================================================================================
    # arming
    def arm(self, sim_t: float) -> int:
        if self.terminated:
            self.event("arming denied: flight terminated", M.MAV_SEVERITY_CRITICAL)
            return M.MAV_RESULT_DENIED
        if self.armed:
            return M.MAV_RESULT_ACCEPTED
        self.armed = True
        if not self.ever_armed:
            self.ever_armed = True
            self.release_requested = True
        if self.mode in ("HOLD", "POSCTL"):
            self.fs.engage("hold", self.p(), float(self.dyn.att[self.idx, 2]))
        elif self.mode == "LAND":
            self.fs.engage("land", self.p(), float(self.dyn.att[self.idx, 2]))
        self._landed_since = None
        self.event("armed")
        return M.MAV_RESULT_ACCEPTED

    def disarm(self, force: bool, why: str = "") -> int:
        if not self.armed:
            return M.MAV_RESULT_ACCEPTED
        if not force and not self.on_ground():
            self.event("disarm denied: not landed", M.MAV_SEVERITY_WARNING)
            return M.MAV_RESULT_DENIED
        self.armed = False
        self.failsafe = False
        self.release_requested = True  # a forced disarm drops it, fixture or not
        self.event("disarmed" + (f" ({why})" if why else ""))
        return M.MAV_RESULT_ACCEPTED

    def terminate(self) -> int:
        self.terminated = True
        self.armed = False
        self.failsafe = False
        self.release_requested = True
        self.event("FLIGHT TERMINATION: motors off", M.MAV_SEVERITY_EMERGENCY)
        return M.MAV_RESULT_ACCEPTED

    # ==================================================================================
    # message handling
    def handle(self, m, src=None, wall: float = 0.0, sim_t: float = 0.0) -> None:
        """Process one decoded message received on ``src`` = (link_name, addr)."""
        tgt = getattr(m, "target_system", 0)
        if tgt not in (0, self.id):
            self.ctr.commands_foreign += 1
            return
        mid = m.get_msgId()
        if mid == M.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET:
            self._on_setpoint(m, sim_t)
        elif mid == M.MAVLINK_MSG_ID_COMMAND_LONG:
            tc = getattr(m, "target_component", 0)
            if tc not in (0, 1):
                self.ctr.commands_foreign += 1
                return
            p = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
            self._on_command(m, src, m.command, p, wall, sim_t)
        elif mid == M.MAVLINK_MSG_ID_COMMAND_INT:
            tc = getattr(m, "target_component", 0)
            if tc not in (0, 1):
                self.ctr.commands_foreign += 1
                return
            p = (m.param1, m.param2, m.param3, m.param4, m.x * 1e-7, m.y * 1e-7, m.z)
            self._on_command(m, src, m.command, p, wall, sim_t, is_int=True)
        elif mid == M.MAVLINK_MSG_ID_SET_MODE:
            if m.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                main = (m.custom_mode >> 16) & 0xFF
                sub = (m.custom_mode >> 24) & 0xFF
                res = self.request_mode(main, sub, sim_t)
            else:
                res = M.MAV_RESULT_UNSUPPORTED
            self._ack(src, M.MAV_CMD_DO_SET_MODE, res, m)
        elif mid == M.MAVLINK_MSG_ID_TIMESYNC:
            if m.tc1 == 0:
                now_ns = int(round(sim_t * 1e9))
                self._reply(M.MAVLink_timesync_message(now_ns, m.ts1), src)
        # HEARTBEAT and everything else from a GCS: nothing to do

    def _on_setpoint(self, m, sim_t: float) -> None:
        tm = int(m.type_mask)
        att_ignore = bool(tm & TM_ATT_IGNORE)
        thr_ignore = bool(tm & TM_THRUST_IGNORE)
        rates_given = (tm & TM_RATES_IGNORE) != TM_RATES_IGNORE
        if att_ignore and rates_given:  # pure body-rate control: not supported
            self.ctr.setpoints_unsupported += 1
            self.ctr.setpoints_rejected += 1
            return
        att = None
        thrust = None
        if not att_ignore:
            q = np.asarray(m.q, dtype=float)
            if not frames.valid_quaternion(q):
                self.ctr.setpoints_rejected += 1
                return
            att = frames.euler_enu_from_quat_ned(q)
            if not all(math.isfinite(a) for a in att):
                self.ctr.setpoints_rejected += 1
                return
        if not thr_ignore:
            th = float(m.thrust)
            if not (math.isfinite(th) and 0.0 <= th <= 1.0):
                self.ctr.setpoints_rejected += 1
                return
            thrust = frames.norm_to_thrust(th, self.dyn.f_max)
        w = self.odom_wall.pop(int(m.time_boot_ms), None)
        if w is not None:
            self.latency.append(time.monotonic() - w)
        if self.cfg.lockstep:
            if int(m.time_boot_ms) != self.expect_ms:
                self.ctr.setpoints_stale += 1
                return
            self.answered_ms = self.expect_ms
            self.ever_answered = True
            self.consecutive_timeouts = 0
            self.wait_suspended = False
        self.ctr.setpoints += 1
        if att is not None:
            self.sp_att = np.array(att, dtype=float)
        if thrust is not None:
            self.sp_thrust = thrust
        self.sp_times.append(sim_t)
        self.last_sp_t = sim_t
        self.last_sp_ms = int(m.time_boot_ms)

    def _on_command(self, m, src, cmd: int, p, wall: float, sim_t: float, is_int=False) -> None:
        self.ctr.commands += 1
        res = M.MAV_RESULT_UNSUPPORTED
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            want = _finite(p[0])
            force = _finite(p[1], 0.0) == FORCE_MAGIC
            if want is None:
                res = M.MAV_RESULT_DENIED
            elif want > 0.5:
                res = self.arm(sim_t)
            else:
                res = self.disarm(force, "forced" if force else "")
        elif cmd == M.MAV_CMD_DO_SET_MODE:
            base = _finite(p[0])
            main = _finite(p[1])
            sub = _finite(p[2], 0.0)
            if (
                base is None
                or main is None
                or not (int(base) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
            ):
                res = M.MAV_RESULT_UNSUPPORTED
            else:
                res = self.request_mode(int(main), int(sub), sim_t)
        elif cmd == M.MAV_CMD_NAV_LAND:
            res = self.request_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_LAND, sim_t)
        elif cmd == M.MAV_CMD_NAV_LOITER_UNLIM:
            res = self.request_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER, sim_t)
        elif cmd == M.MAV_CMD_DO_FLIGHTTERMINATION:
            on = _finite(p[0], 0.0)
            res = self.terminate() if on > 0.5 else M.MAV_RESULT_ACCEPTED
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            res = self._set_interval(_finite(p[0]), _finite(p[1]), wall)
        elif cmd == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            mid = _finite(p[0])
            if mid is None or int(mid) not in self.intervals:
                res = M.MAV_RESULT_UNSUPPORTED
            else:
                iv = self.intervals[int(mid)]
                self._ack(src, cmd, M.MAV_RESULT_ACCEPTED, m)
                self._reply(
                    M.MAVLink_message_interval_message(int(mid), int(iv * 1e6) if iv else -1), src
                )
                return
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            mid = _finite(p[0])
            msg = self.build(int(mid), sim_t) if mid is not None and 0 <= mid < 2**24 else None
            if msg is None:
                res = M.MAV_RESULT_UNSUPPORTED
            else:
                self._ack(src, cmd, M.MAV_RESULT_ACCEPTED, m)
                self._reply(msg, src)
                return
        elif cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            if _finite(p[0], 1.0) > 0.5:
                self._ack(src, cmd, M.MAV_RESULT_ACCEPTED, m)
                self._reply(self.build(MSG_AUTOPILOT_VERSION, sim_t), src)
                return
            res = M.MAV_RESULT_ACCEPTED
        if res == M.MAV_RESULT_UNSUPPORTED:
            self.ctr.commands_unsupported += 1
        self._ack(src, cmd, res, m)

    def _set_interval(self, mid: float | None, interval_us: float | None, wall: float) -> int:
        if mid is None or interval_us is None or int(mid) not in self.intervals:
            return M.MAV_RESULT_UNSUPPORTED
        mid_i = int(mid)
        if interval_us < 0:
            self.intervals[mid_i] = 0.0
        elif interval_us == 0:
            hz = self.cfg.odometry_hz if mid_i == MSG_ODOMETRY else self.cfg.rates.get(mid_i, 0.0)
            self.intervals[mid_i] = 1.0 / hz if hz > 0 else 0.0
        else:
            self.intervals[mid_i] = min(max(interval_us * 1e-6, 1e-3), 2000.0)  # fits int32 µs
        if mid_i == MSG_HEARTBEAT:  # the link's liveness: never off, at least 1 Hz
            iv = self.intervals[mid_i]
            self.intervals[mid_i] = min(1.0, max(0.02, iv if iv > 0 else 1.0))
        self._next_due[mid_i] = wall
        return M.MAV_RESULT_ACCEPTED

    # ==================================================================================
    # per control step
    def update(self, sim_t: float) -> None:
        """Offboard-loss failsafe and auto-disarm after landing (call once per step)."""
        if (
            self.mode == "OFFBOARD"
            and not self.failsafe
            and (self.last_sp_t is None or sim_t - self.last_sp_t > self.cfg.offboard_timeout)
        ):
            self.ctr.failsafes += 1
            target = "LAND" if self.cfg.failsafe == "land" else "HOLD"
            self.event(f"failsafe: offboard lost, {target.lower()}", M.MAV_SEVERITY_CRITICAL)
            self._enter_mode(target, sim_t)
            self.failsafe = True
        if self.mode == "LAND" and self.armed:
            if self.on_ground():
                if self._landed_since is None:
                    self._landed_since = sim_t
                elif sim_t - self._landed_since >= self.cfg.land_disarm_delay:
                    self.disarm(force=False, why="landed")
            else:
                self._landed_since = None

    def command(self, dt: float) -> tuple[float, float, float, float]:
        """(roll, pitch, yaw, thrust N) to apply for the next control step."""
        i = self.idx
        if not self.armed:
            # motors off once it has flown; before that, hover thrust on the spawn fixture
            thrust = 0.0 if (self.ever_armed or self.terminated) else float(self.dyn.hold_thrust())
            return 0.0, 0.0, float(self.dyn.att[i, 2]), thrust
        if self.mode == "OFFBOARD" and not self.failsafe:
            r, pch, y = self.sp_att
            return float(r), float(pch), float(y), float(self.sp_thrust)
        return self.fs.update(self.dyn.p[i], self.dyn.v[i], dt)

    # ==================================================================================
    # telemetry
    def landed_state(self) -> int:
        if self.on_ground():
            return M.MAV_LANDED_STATE_ON_GROUND
        if self.armed and self.mode == "LAND":
            return M.MAV_LANDED_STATE_LANDING
        return M.MAV_LANDED_STATE_IN_AIR

    def heartbeat(self):
        base = (
            M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            | M.MAV_MODE_FLAG_GUIDED_ENABLED
        )
        if self.mode == "POSCTL":
            base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        else:
            base |= M.MAV_MODE_FLAG_AUTO_ENABLED
        if self.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if self.terminated:
            status = M.MAV_STATE_FLIGHT_TERMINATION
        else:
            status = M.MAV_STATE_ACTIVE if self.armed else M.MAV_STATE_STANDBY
        return M.MAVLink_heartbeat_message(
            M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, base, self.custom_mode, status, 3
        )

    def _q_ned(self) -> np.ndarray:
        r, p, y = self.dyn.att[self.idx]
        return frames.quat_ned_from_euler_enu(float(r), float(p), float(y))

    def _rates_frd(self) -> tuple[float, float, float]:
        """Body rates (FRD) approximated by the Euler-angle rates of the attitude lag."""
        d = self.dyn
        rate = (d.cmd_att[self.idx] - d.att[self.idx]) / d.tau
        return float(rate[0]), float(-rate[1]), float(-rate[2])

    def _latlon(self, ned: np.ndarray) -> tuple[int, int]:
        c = self.cfg
        lat = c.home_lat + math.degrees(ned[0] / EARTH_R)
        lon = c.home_lon + math.degrees(ned[1] / (EARTH_R * math.cos(math.radians(c.home_lat))))
        return int(round(lat * 1e7)), int(round(lon * 1e7))

    def odometry(self, sim_t: float):
        i = self.idx
        stamp = int(round(sim_t * 1000))
        if stamp not in self.odom_wall:  # a re-send keeps the first send time
            if len(self.odom_wall) > 256:
                self.odom_wall.clear()
            self.odom_wall[stamp] = time.monotonic()
        pn = frames.enu_to_ned(self.dyn.p[i])
        vn = frames.enu_to_ned(self.dyn.v[i])
        q = self._q_ned()
        r_ned = frames.rotm_from_quat(q)
        vb = r_ned.T @ vn  # body FRD velocity (child_frame_id = BODY_FRD)
        wr = self._rates_frd()
        nan21 = [math.nan] * 21
        return M.MAVLink_odometry_message(
            int(round(sim_t * 1e6)),
            M.MAV_FRAME_LOCAL_NED,
            M.MAV_FRAME_BODY_FRD,
            float(pn[0]), float(pn[1]), float(pn[2]),
            [float(x) for x in q],
            float(vb[0]), float(vb[1]), float(vb[2]),
            wr[0], wr[1], wr[2],
            nan21, nan21, 0, M.MAV_ESTIMATOR_TYPE_NAIVE, 100,
        )  # fmt: skip

    def build(self, mid: int, sim_t: float):
        """Build message ``mid`` from the current state (None if not supported)."""
        i = self.idx
        t_ms = int(round(sim_t * 1000)) & 0xFFFFFFFF
        if mid == MSG_HEARTBEAT:
            return self.heartbeat()
        if mid == MSG_ODOMETRY:
            return self.odometry(sim_t)
        if mid == MSG_ATTITUDE_QUATERNION:
            q = self._q_ned()
            wr = self._rates_frd()
            return M.MAVLink_attitude_quaternion_message(
                t_ms, float(q[0]), float(q[1]), float(q[2]), float(q[3]), *wr
            )
        if mid == MSG_ATTITUDE:
            q = self._q_ned()
            rn, pn, yn = frames.euler_from_rotm(frames.rotm_from_quat(q))
            return M.MAVLink_attitude_message(t_ms, rn, pn, yn, *self._rates_frd())
        if mid == MSG_LOCAL_POSITION_NED:
            pn = frames.enu_to_ned(self.dyn.p[i])
            vn = frames.enu_to_ned(self.dyn.v[i])
            return M.MAVLink_local_position_ned_message(t_ms, *map(float, pn), *map(float, vn))
        if mid == MSG_GLOBAL_POSITION_INT:
            pn = frames.enu_to_ned(self.dyn.p[i])
            vn = frames.enu_to_ned(self.dyn.v[i])
            lat, lon = self._latlon(pn)
            yaw_ned = math.pi / 2 - float(self.dyn.att[i, 2])
            hdg = int(round(math.degrees(yaw_ned) % 360.0 * 100)) % 36000
            return M.MAVLink_global_position_int_message(
                t_ms, lat, lon,
                int(round((self.cfg.home_alt - pn[2]) * 1000)), int(round(-pn[2] * 1000)),
                *(int(max(-32768, min(32767, round(x * 100)))) for x in vn), hdg,
            )  # fmt: skip
        if mid == MSG_GPS_RAW_INT:
            pn = frames.enu_to_ned(self.dyn.p[i])
            lat, lon = self._latlon(pn)
            return M.MAVLink_gps_raw_int_message(
                int(round(sim_t * 1e6)), M.GPS_FIX_TYPE_3D_FIX, lat, lon,
                int(round((self.cfg.home_alt - pn[2]) * 1000)), 80, 120, 0, 65535, 16,
            )  # fmt: skip
        if mid == MSG_HOME_POSITION:
            h = self.home_ned
            lat, lon = self._latlon(h)
            return M.MAVLink_home_position_message(
                lat, lon, int(round(self.cfg.home_alt * 1000)),
                float(h[0]), float(h[1]), float(h[2]), [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                int(round(sim_t * 1e6)),
            )  # fmt: skip
        if mid == MSG_EXTENDED_SYS_STATE:
            return M.MAVLink_extended_sys_state_message(
                M.MAV_VTOL_STATE_UNDEFINED, self.landed_state()
            )
        if mid == MSG_SYS_STATUS:
            return M.MAVLink_sys_status_message(
                SENSORS, SENSORS, SENSORS, 100, 16200, 1000, 100, 0, 0, 0, 0, 0, 0
            )
        if mid == MSG_AUTOPILOT_VERSION:
            caps = (
                M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
                | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            )
            return M.MAVLink_autopilot_version_message(
                caps, (1 << 24) | (15 << 16) | (0 << 8) | 255, 0, 0, 0,
                [0] * 8, [0] * 8, [0] * 8, 0x1209, 0x5353, self.uid & 0xFFFFFFFFFFFFFFFF,
                list(self.uid.to_bytes(8, "little")) + [0] * 10,
            )  # fmt: skip
        if mid == MSG_ATTITUDE_TARGET:
            q = frames.quat_ned_from_euler_enu(*map(float, self.sp_att))
            return M.MAVLink_attitude_target_message(
                t_ms, TM_RATES_IGNORE, [float(x) for x in q], 0.0, 0.0, 0.0,
                frames.thrust_to_norm(self.sp_thrust, self.dyn.f_max),
            )  # fmt: skip
        return None

    def periodic(self, wall: float, sim_t: float, skip: tuple[int, ...] = ()) -> None:
        """Queue every stream whose interval has elapsed on the wall clock."""
        for mid, iv in self.intervals.items():
            if iv <= 0 or mid in skip:
                continue
            due = self._next_due.get(mid)
            if due is None:
                due = wall
            if wall + 1e-3 >= due:
                msg = self.build(mid, sim_t)
                if msg is not None:
                    self.outbox.append((msg, None))
                due += iv
                if due < wall:
                    due = wall + iv
            self._next_due[mid] = due

    def pack(self, msg) -> bytes:
        """Encode with this vehicle's sequence counter (sysid = agent id, compid 1)."""
        buf = msg.pack(self.enc)
        self.enc.seq = (self.enc.seq + 1) % 256
        return buf
