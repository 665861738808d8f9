"""The formation as one MAVLink vehicle (docs/missions.md, "The formation as one vehicle").

A ground station (QGroundControl, MAVProxy, MAVSDK, pymavlink) talks to the whole formation
as to one PX4 vehicle, system id :data:`FORMATION_SYSID`, on UDP :data:`FORMATION_PORT` +
offset on the ground-station host. It sees the formation's centroid as the vehicle's position.
It uploads, downloads and starts a mission, sends it somewhere (``DO_REPOSITION``), holds it
(``DO_SET_MODE`` AUTO.LOITER), changes its speed (``DO_CHANGE_SPEED``) and its scale (the
``FORM_SCALE`` parameter), or flies it live in OFFBOARD with velocity or position setpoints
(:mod:`gcs.formation.live`). Each of these becomes a Zenoh ``mission``, ``hold`` or ``live``
command to the leaders, timed :data:`gcs.formation.steer.COMMAND_LEAD_S` of mission time ahead so
that every leader applies it at the same step (:mod:`swarm_common.mission.timeline`).

The vehicle keeps a replica of the leaders' timeline. It refuses a mission or command that the
leaders could not fly (a waypoint under the floor, too dense, too fast) with
``MAV_MISSION_INVALID`` or ``MAV_RESULT_DENIED``, before anything is sent. The mission transfer
protocol is the simulator's own (:mod:`vehicle_sim.services.mission_transfer`).

With a signing key, every frame it sends is signed and every frame it takes must carry a valid
signature of that key: the formation is flown only by a ground station that holds the key.
"""

from __future__ import annotations

import copy
import logging
import math
import socket
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from gcs.formation.live import LiveSetpoints, parse_setpoint
from gcs.formation.steer import FormationSteer
from gcs.formation.translate import items_to_table, yaw_of_heading
from swarm_common import frames, px4, wire
from swarm_common.mission.config import MissionError
from swarm_common.scenario.spec import Scenario
from swarm_common.signing import setup_signing
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics import geo
from vehicle_sim.services import mission_items as mi
from vehicle_sim.services.mission_transfer import MissionTransfer

log = logging.getLogger(__name__)

FORMATION_SYSID = 200
FORMATION_PORT = 14560  # + offset; free in the vehicles' port scheme (swarm_common.ports)
HEARTBEAT_S = 1.0
POSITION_S = 0.25
REPEATS, REPEAT_S = 5, 0.5  # copies of each command after the first, and their spacing (s)
MAX_DATAGRAM = 2048
Publish = Callable[[wire.Command], None]


class FormationVehicle:
    """The formation's MAVLink endpoint. Call :meth:`serve` often (the runner's step hook):
    it reads what came in, answers it, publishes commands and sends telemetry."""

    def __init__(
        self, sc: Scenario, publish: Publish, port: int, host: str = "127.0.0.1",
        key: bytes | None = None, steer: FormationSteer | None = None,
    ) -> None:
        self.sc, self.publish = sc, publish
        # a shared steering (the dashboard's); raises MissionError without a [mission]
        self.steer = steer if steer is not None else FormationSteer(sc)
        self.base = self.steer.base
        self.geo = AutopilotConfig()
        self.transfer = MissionTransfer(self.geo)
        self.mav = M.MAVLink(None, srcSystem=FORMATION_SYSID, srcComponent=1)
        if key is not None:
            setup_signing(self.mav, key, 0)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.clients: set[tuple[str, int]] = set()
        self.t = 0.0  # mission time of the latest truth (s)
        self.centroid = np.full(3, np.nan)
        self.velocity = np.zeros(3)
        self.bad_frames = 0
        self.live = False  # the swarm is stepping (a truth came): commands reach the leaders
        self.sent_commands: list[wire.Command] = []
        self.setpoints = LiveSetpoints(self.base.max_speed_mps)
        self.offboard = False  # flown live by a client's setpoints (gcs.formation.live)
        self._pending: list[tuple[float, wire.Command, int]] = []  # (due, command, copies left)
        self._next_hb = self._next_pos = 0.0
        self._t_boot = time.monotonic()

    def close(self) -> None:
        self.sock.close()

    # -- the loop ------------------------------------------------------------------
    def serve(self, t: float, p: np.ndarray | None, v: np.ndarray | None) -> None:
        """Take the truth of mission time ``t`` (every agent's p, v (N, 3), or None), answer
        what came in, send what is due."""
        self.t = float(t)
        if p is not None and np.all(np.isfinite(p)):
            self.centroid = p.mean(axis=0)
            self.live = True
            if v is not None and np.all(np.isfinite(v)):
                self.velocity = v.mean(axis=0)
        now = time.monotonic()
        self._repeat(now)
        while True:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # e.g. ICMP port unreachable of a gone client
                log.debug("formation vehicle: %s", exc)
                break
            if self.live:  # before the swarm steps nobody would hear a command: silent
                self._take(data, addr)
        if not self.live:
            return
        self._fly_live(now)
        for m, dest in self.transfer.tick(now):
            self._send(m, dest)
        self._transfer_errors()
        if now >= self._next_hb:
            self._next_hb = now + HEARTBEAT_S
            self._broadcast(self._heartbeat())
            self._broadcast(M.MAVLink_mission_current_message(self._progress()))
        if now >= self._next_pos and np.all(np.isfinite(self.centroid)):
            self._next_pos = now + POSITION_S
            for m in self._position():
                self._broadcast(m)

    def _take(self, data: bytes, addr: tuple[str, int]) -> None:
        """One datagram: whole frames only (a datagram's leftover bytes are a bad frame,
        dropped, never joined with the next datagram's)."""
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - pymavlink raises many kinds on garbage
            msgs = None
        if msgs is None or self.mav.buf_len() > 0:
            self.bad_frames += 1
            self.mav.buf, self.mav.buf_index = bytearray(), 0
            self.mav.expected_length = M.HEADER_LEN_V1 + 2
            if msgs is None:
                return
        for m in msgs:
            if m.get_type() == "BAD_DATA":
                self.bad_frames += 1
                continue
            self.clients.add(addr)
            try:
                self._handle(m, addr)
            except (ValueError, OverflowError) as exc:  # fields no handler can use
                self.bad_frames += 1
                log.info("formation vehicle: %s dropped (%s)", m.get_type(), exc)

    # -- messages in ---------------------------------------------------------------
    def _handle(self, m: Any, addr: tuple[str, int]) -> None:
        kind = m.get_type()
        target = getattr(m, "target_system", FORMATION_SYSID)
        if target not in (0, FORMATION_SYSID):
            return
        now = time.monotonic()
        out: list[tuple[Any, Any]] = []
        if kind == "MISSION_COUNT":
            out = self.transfer.on_count(m, addr, now)
        elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            before = list(self.transfer.stores[mi.MISSION])
            out = self.transfer.on_item(m, addr, now, kind == "MISSION_ITEM_INT")
            out = self._check_upload(out, before)
        elif kind == "MISSION_REQUEST_LIST":
            out = self.transfer.on_request_list(m, addr)
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            out = self.transfer.on_request(m, addr, kind == "MISSION_REQUEST_INT")
        elif kind == "MISSION_CLEAR_ALL":
            out = self.transfer.on_clear_all(m, addr)
        elif kind == "MISSION_ACK":
            self.transfer.on_client_ack(m)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            out = [(self._command(m, kind == "COMMAND_INT"), addr)]
        elif kind == "PARAM_REQUEST_LIST":
            out = [(self._param_value(), addr)]
        elif kind == "PARAM_REQUEST_READ":
            out = [(self._param_value(), addr)]
        elif kind == "PARAM_SET":
            out = [(self._param_set(m), addr)]
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.setpoints.take(parse_setpoint(m, now))  # MissionError: counted, dropped
        self.transfer.changed.clear()
        for msg, dest in out:
            self._send(msg, dest)

    def _check_upload(self, out: list[tuple[Any, Any]], before: list[Any]) -> list[Any]:
        """An upload the transfer accepted must also be a flyable formation mission: else
        the old store comes back and the final ACK says MAV_MISSION_INVALID."""
        if mi.MISSION not in self.transfer.changed or not self.transfer.stores[mi.MISSION]:
            return out
        try:
            self._dry_run(self._store_table())
        except MissionError as exc:
            self.transfer.stores[mi.MISSION] = before
            log.warning("formation vehicle: mission refused: %s", exc)
            return [(M.MAVLink_mission_ack_message(m.target_system, m.target_component,
                                                   M.MAV_MISSION_INVALID, mi.MISSION), d)
                    if m.get_type() == "MISSION_ACK" else (m, d) for m, d in out]
        return out

    def _store_table(self) -> dict[str, Any]:
        st = self.steer
        return items_to_table(self.geo, self.transfer.stores[mi.MISSION], st.speed, st.scale,
                              st.yaw_deg, self.base)

    def _dry_run(self, table: dict[str, Any]) -> None:
        """Refuse (MissionError) what the leaders could not fly from their next rest."""
        copy.deepcopy(self.steer).fly(table, self.t)

    # -- commands --------------------------------------------------------------------
    def _command(self, m: Any, is_int: bool) -> Any:
        cmd = int(m.command)
        result = M.MAV_RESULT_UNSUPPORTED
        try:
            if cmd == M.MAV_CMD_MISSION_START:
                result = self._fly(self._store_table())
            elif cmd == M.MAV_CMD_DO_REPOSITION:
                result = self._reposition(m, is_int)
            elif cmd == M.MAV_CMD_DO_CHANGE_SPEED:
                speed = float(m.param2)
                if not (math.isfinite(speed) and 0.0 < speed <= self.base.max_speed_mps):
                    raise MissionError(f"speed {speed!r}: must be in (0, "
                                       f"{self.base.max_speed_mps:g}] m/s")
                self.steer.speed, result = speed, M.MAV_RESULT_ACCEPTED
            elif cmd == M.MAV_CMD_DO_SET_MODE:
                result = self._set_mode(m)
        except MissionError as exc:
            log.warning("formation vehicle: command %d denied: %s", cmd, exc)
            result = M.MAV_RESULT_DENIED
        return M.MAVLink_command_ack_message(cmd, result, 0, 0, m.get_srcSystem(),
                                             m.get_srcComponent())

    def _reposition(self, m: Any, is_int: bool) -> int:
        lat, lon = (m.x / 1e7, m.y / 1e7) if is_int else (float(m.param5), float(m.param6))
        alt = float(m.z) if is_int else float(m.param7)
        if not all(math.isfinite(x) for x in (lat, lon, alt)):
            raise MissionError("reposition: latitude, longitude and altitude must be numbers")
        north, east = geo.ned_from_latlon(self.geo, lat, lon)
        frame = int(getattr(m, "frame", M.MAV_FRAME_GLOBAL))
        up = alt if frame in mi.RELATIVE_FRAMES else -geo.down_from_amsl(self.geo, alt)
        if float(m.param1) > 0.0:
            self.steer.speed = min(float(m.param1), self.base.max_speed_mps)
        # NaN heading: keep the formation's yaw (FormationSteer.goto)
        yaw = None if math.isnan(float(m.param4)) else yaw_of_heading(float(m.param4), 0.0)
        return self._publish_cmd(self.steer.goto(np.array([east, north, up]), self.t, yaw))

    def _set_mode(self, m: Any) -> int:
        main, sub = int(m.param2), int(m.param3)
        if main == px4.MAIN_OFFBOARD:  # as PX4: only once setpoints stream
            if not self.setpoints.fresh(time.monotonic()):
                raise MissionError("OFFBOARD refused: no setpoint stream")
            self.offboard = True
            self.setpoints.restart()  # the first live command goes at once
            return M.MAV_RESULT_ACCEPTED
        self.offboard = False
        if main == px4.MAIN_AUTO and sub == px4.SUB_AUTO_LOITER:
            return self._publish_cmd(self.steer.hold(self.t))
        if main == px4.MAIN_AUTO and sub == px4.SUB_AUTO_MISSION:
            return self._fly(self._store_table())
        return M.MAV_RESULT_UNSUPPORTED

    def _fly(self, table: dict[str, Any]) -> int:
        self.offboard = False
        return self._publish_cmd(self.steer.fly(table, self.t))

    def _fly_live(self, now: float) -> None:
        """In OFFBOARD: the velocity of the latest setpoint to the leaders when due; a
        stream gone quiet ends OFFBOARD (the leaders' plan brakes to rest by itself)."""
        if not self.offboard:
            return
        if not self.setpoints.fresh(now):
            self.offboard, self.steer.holding = False, True
            log.warning("formation vehicle: setpoints lost: the formation brakes and holds")
            return
        v = self.setpoints.velocity(self.steer.centroid_at_command(self.t))
        if not self.setpoints.due(self.t, v):
            return
        try:
            cmd = self.steer.live(v, self.t)
        except MissionError as exc:  # e.g. it would take an agent under the floor: stop
            log.warning("formation vehicle: setpoint refused: %s", exc)
            v = np.zeros(3)
            try:
                cmd = self.steer.live(v, self.t)
            except MissionError:
                return
        self.setpoints.sent(self.t, v)
        self._pending.clear()  # older commands' copies would arrive out of order
        self.publish(cmd)
        self.sent_commands.append(cmd)

    def _publish_cmd(self, cmd: wire.Command) -> int:
        """Publish a command the steering accepted (a refused one raised MissionError: the
        caller answers DENIED, nothing sent), and its repeats later."""
        self.publish(cmd)
        self._pending.append((time.monotonic() + REPEAT_S, cmd, REPEATS))
        self.sent_commands.append(cmd)
        log.info("formation vehicle: %s at t=%.2f s", cmd.kind, cmd.at_s)
        return M.MAV_RESULT_ACCEPTED

    def _repeat(self, now: float) -> None:
        """Publish each command again REPEATS times, REPEAT_S apart: a Zenoh put is lost to
        a daemon whose link is reconnecting, and the leaders apply copies (the same at_s)
        idempotently (:mod:`swarm_common.mission.timeline`)."""
        keep = []
        for due, cmd, left in self._pending:
            if now >= due:
                self.publish(cmd)
                due, left = now + REPEAT_S, left - 1
            if left > 0:
                keep.append((due, cmd, left))
        self._pending = keep

    # -- parameters ------------------------------------------------------------------
    def _param_value(self) -> Any:
        return M.MAVLink_param_value_message(b"FORM_SCALE", self.steer.scale,
                                             M.MAV_PARAM_TYPE_REAL32, 1, 0)

    def _param_set(self, m: Any) -> Any:
        name = bytes(m.param_id, "ascii", "replace") if isinstance(m.param_id, str) else m.param_id
        if name.rstrip(b"\0") != b"FORM_SCALE":
            return self._param_value()
        value = float(m.param_value)
        try:
            if not (math.isfinite(value) and 0.0 < value <= 10.0):
                raise MissionError(f"FORM_SCALE {value!r}: must be in (0, 10]")
            self._publish_cmd(self.steer.nudge(self.t, scale_by=value / self.steer.rest_pose(
                self.t).scale))
        except MissionError as exc:
            log.warning("formation vehicle: FORM_SCALE refused: %s", exc)
        return self._param_value()

    # -- telemetry -------------------------------------------------------------------
    def _progress(self) -> int:
        plan = self.steer.timeline.plan_at(self.t)
        return min(plan.waypoint_at(self.t), max(len(plan.legs) - 1, 0))

    def _heartbeat(self) -> Any:
        sub = px4.SUB_AUTO_LOITER if self.steer.holding else px4.SUB_AUTO_MISSION
        custom = (px4.MAIN_OFFBOARD << 16 if self.offboard
                  else (px4.MAIN_AUTO << 16) | (sub << 24))
        base = (mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                | mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
                | mavutil.mavlink.MAV_MODE_FLAG_AUTO_ENABLED)
        return M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, base,
                                           custom, M.MAV_STATE_ACTIVE, 3)

    def _position(self) -> list[Any]:
        ned = frames.enu_to_ned(self.centroid)
        vel = frames.enu_to_ned(self.velocity)
        ms = int((time.monotonic() - self._t_boot) * 1000) & 0xFFFFFFFF
        lat, lon = geo.latlon_e7(self.geo, ned)
        alt_mm = int(round(-float(ned[2]) * 1000))
        return [
            M.MAVLink_local_position_ned_message(ms, *(float(x) for x in ned),
                                                 *(float(x) for x in vel)),
            M.MAVLink_global_position_int_message(
                ms, lat, lon, int(round((self.geo.home_alt - float(ned[2])) * 1000)), alt_mm,
                *(int(round(float(x) * 100)) for x in vel), 65535),
        ]

    # -- sending ---------------------------------------------------------------------
    def _send(self, m: Any, dest: Any) -> None:
        try:
            self.sock.sendto(m.pack(self.mav), dest)
        except OSError as exc:
            log.debug("formation vehicle: send to %s: %s", dest, exc)

    def _broadcast(self, m: Any) -> None:
        for c in list(self.clients):
            self._send(m, c)

    def _transfer_errors(self) -> None:
        for line in self.transfer.errors:
            log.info("formation vehicle: %s", line)
        self.transfer.errors.clear()
