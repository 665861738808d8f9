"""Before its lock, the daemon's vehicle link asks the vehicle for a HEARTBEAT
(MAV_CMD_REQUEST_MESSAGE) when a decoded, verified frame of that vehicle arrives, instead
of waiting for the 1 Hz stream; nothing goes to a stranger or on a frame that fails its
signature, and the lock still takes the HEARTBEAT. Real UDP on loopback, frames packed
by pymavlink."""

import os
import socket
import time

from conftest import free_port_offset, received_frames, wait_for  # noqa: E402

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from offboard.daemon.mavlink.link import HEARTBEAT_ASK_S, VehicleLink  # noqa: E402
from swarm_common.ports import vehicle_ports  # noqa: E402
from swarm_common.signing import setup_signing  # noqa: E402

M = mavutil.mavlink
KEY = bytes(range(32))


def _odometry(mav: object) -> bytes:
    odo = M.MAVLink_odometry_message(
        1000, 1, 12, 1.0, 2.0, -3.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        [float("nan")] * 21, [float("nan")] * 21)
    return bytes(odo.pack(mav))


def _requests(msgs: list[object]) -> list[object]:
    return [m for m in msgs if m.get_type() == "COMMAND_LONG"
            and m.command == M.MAV_CMD_REQUEST_MESSAGE
            and int(m.param1) == M.MAVLINK_MSG_ID_HEARTBEAT]


def test_a_verified_frame_before_the_lock_asks_for_the_heartbeat() -> None:
    port = vehicle_ports(2, free_port_offset()).api_remote
    link = VehicleLink(f"udpin:127.0.0.1:{port}", 2, 50.0, lockstep=True, signing_key=KEY)
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.2)
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.bind(("127.0.0.1", 0))
    stranger.settimeout(0.2)
    signed = M.MAVLink(None, srcSystem=2, srcComponent=1)
    setup_signing(signed, KEY, link_id=1)
    unsigned = M.MAVLink(None, srcSystem=2, srcComponent=1)
    other = M.MAVLink(None, srcSystem=7, srcComponent=1)
    other_signed = M.MAVLink(None, srcSystem=7, srcComponent=1)
    setup_signing(other_signed, KEY, link_id=3)

    def poll_until(pred) -> bool:
        def step() -> object:
            link.poll(0.05)
            return pred()
        return wait_for(step)

    try:
        # an unsigned frame claiming the vehicle, and a signed one of another system:
        # dropped and counted, and nothing is sent to anyone
        stranger.sendto(_odometry(unsigned), ("127.0.0.1", port))
        stranger.sendto(_odometry(other_signed), ("127.0.0.1", port))
        stranger.sendto(_odometry(other), ("127.0.0.1", port))
        assert poll_until(lambda: link.drops.total >= 3)
        assert received_frames(stranger) == [] and not link.locked
        # the vehicle's verified ODOMETRY, five times: a request for its HEARTBEAT, to it,
        # and at most one per HEARTBEAT_ASK_S whatever the number of frames
        got: list[object] = []
        start = time.monotonic()
        for _ in range(5):
            vehicle.sendto(_odometry(signed), ("127.0.0.1", port))
        assert poll_until(lambda: bool(_requests(got)) or got.extend(received_frames(vehicle)))
        link.poll(0.05)
        got.extend(received_frames(vehicle))
        elapsed = time.monotonic() - start
        asks = _requests(got)
        assert 1 <= len(asks) <= 1 + elapsed // HEARTBEAT_ASK_S, (len(asks), elapsed)
        req = asks[0]
        assert (req.target_system, req.target_component) == (2, 1)
        assert req.get_srcSystem() == 2 and req.get_srcComponent() == 191
        assert req.get_msgbuf()[2] & M.MAVLINK_IFLAG_SIGNED  # signed like every frame
        assert not link.locked  # the lock still takes the HEARTBEAT
        # a signed link first challenges the address (lock_gate): the vehicle echoes ts1
        challenge = next(m for m in got if m.get_type() == "TIMESYNC")
        vehicle.sendto(bytes(M.MAVLink_timesync_message(1, challenge.ts1).pack(signed)),
                       ("127.0.0.1", port))
        vehicle.sendto(bytes(M.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(signed)),
                       ("127.0.0.1", port))
        assert poll_until(lambda: link.locked)
        assert link.peer == vehicle.getsockname()
        assert received_frames(stranger) == []
    finally:
        vehicle.close()
        stranger.close()
        link.close()
