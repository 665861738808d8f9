"""A tiny pymavlink vehicle for link tests: streams to the GCS port, ACKs commands."""

from __future__ import annotations

import socket
import threading
import time

from pymavlink.dialects.v20 import common as mavlink2


class FakeVehicle:
    def __init__(self, sysid: int, gcs_port: int, drop_first_acks: int = 0, ack_result: int = 0):
        self.sysid = sysid
        self.gcs = ("127.0.0.1", gcs_port)
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=1)
        self.rx = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=1)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.custom_mode = 3 << 16
        self.armed = False
        self.drop_first_acks = drop_first_acks
        self.ack_result = ack_result
        self.commands: list[tuple[int, int, list[float]]] = []  # (command, confirmation, params)
        self.heartbeats_from_gcs = 0
        self.t0 = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), self.gcs)

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.gcs)

    def heartbeat(self) -> None:
        base = 1 | (128 if self.armed else 0)
        self.send(self.mav.heartbeat_encode(2, 12, base, self.custom_mode, 4))

    def position(self, ned=(1.0, 2.0, -3.0), vel=(0.5, 0.0, -0.1)) -> None:
        # time_boot_ms runs with the wall clock, as a real-time vehicle's does
        ms = 1000 + int((time.monotonic() - self.t0) * 1000)
        self.send(self.mav.local_position_ned_encode(ms, *ned, *vel))

    def statustext(self, text: str, severity: int = 4) -> None:
        self.send(self.mav.statustext_encode(severity, text.encode()))

    def start(self) -> FakeVehicle:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.sock.close()

    def _run(self) -> None:
        last_hb = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now - last_hb > 0.1:
                last_hb = now
                self.heartbeat()
                self.position()
            try:
                data, addr = self.sock.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            for m in self.rx.parse_buffer(data) or []:
                if m.get_type() == "HEARTBEAT":
                    self.heartbeats_from_gcs += 1
                if m.get_type() != "COMMAND_LONG" or m.target_system != self.sysid:
                    continue
                params = [m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7]
                self.commands.append((m.command, m.confirmation, params))
                if self.drop_first_acks > 0:
                    self.drop_first_acks -= 1
                    continue
                if m.command == 400 and self.ack_result == 0:
                    self.armed = params[0] == 1.0
                if m.command == 176 and self.ack_result == 0:
                    self.custom_mode = int(params[1]) << 16 | int(params[2]) << 24
                ack = self.mav.command_ack_encode(m.command, self.ack_result, 0, 0, 255, 190)
                self.sock.sendto(ack.pack(self.mav), addr)
