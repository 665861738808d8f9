"""The daemon's vehicle link drops telemetry it does not read from the frames' headers
(offboard.daemon.mavlink.frame_peek) and still counts, locks and asks to stop streams as before:
real
UDP on loopback, frames packed by pymavlink."""

import os
import socket

from conftest import free_port_offset, wait_for  # noqa: E402

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.mavlink.link import VehicleLink  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402

M = mavutil.mavlink


def test_unread_frames_are_counted_without_decoding_and_retrigger_the_stop() -> None:
    port = vehicle_ports(1, free_port_offset()).api_remote
    link = VehicleLink(f"udpin:127.0.0.1:{port}", 1, 50.0, lockstep=False)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.1)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    stranger = M.MAVLink(None, srcSystem=9, srcComponent=1)
    attitude = M.MAVLink_attitude_message(1, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)

    def send(frame: bytes) -> None:
        vehicle.sendto(frame, ("127.0.0.1", port))

    def stop_request() -> bool:
        try:
            data = vehicle.recv(2048)
        except TimeoutError:
            return False
        msgs = M.MAVLink(None).parse_buffer(data) or []
        return any(m.get_type() == "REQUEST_DATA_STREAM" and m.start_stop == 0 for m in msgs)

    def polled(pred) -> bool:  # the link read on every try, as the daemon's loop does
        def step() -> object:
            link.poll(0.05)
            return pred()
        return wait_for(step)

    try:
        for _ in range(5):  # before the lock: counted as such, the link stays unlocked
            send(attitude.pack(mav))
        send(M.MAVLink_vfr_hud_message(1.0, 2.0, 90, 50, 3.0, 0.5).pack(stranger))
        assert polled(lambda: link.drops.counts.get("before lock") == 5)
        assert not link.locked and link.drops.counts.get("foreign system") == 1
        send(M.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(mav))
        assert polled(lambda: link.locked)
        # a stream group's message after the lock: the stop request goes to the vehicle
        send(attitude.pack(mav))
        assert polled(stop_request)
        assert link.trim.unread >= 1 and link.trim.requests >= 1
        # a message the daemon reads is still decoded
        odo = M.MAVLink_odometry_message(
            123456, 1, 12, 1.0, 2.0, -3.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            [float("nan")] * 21, [float("nan")] * 21)
        send(odo.pack(mav))
        assert polled(lambda: link.odometry is not None)
        assert link.odometry.z == -3.0
    finally:
        vehicle.close()
        link.close()
