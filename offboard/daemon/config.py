"""The offboard daemon's configuration (``offboard`` command line -> :class:`DaemonConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from offboard.daemon.limits import LAND_AFTER_S, NAV_GATE_M
from swarm_common.enums import Method, SensingSource
from swarm_common.scenario.model import Scenario


@dataclass
class DaemonConfig:
    scenario: Scenario
    agent_id: int
    mavlink_url: str
    swarm: str = "cube8"
    method: Method = Method.RCBF
    seed: int | None = None
    lockstep: bool = True
    tlog: str | None = None
    heartbeat_timeout: float = 30.0
    truth_timeout: float = 2.0
    neighbour_timeout: float = 0.45  # must stay below vehicle-sim --step-timeout (1.0 s)
    vehicle_lost_timeout: float = 5.0
    stream_before_offboard: float = 0.6
    zenoh_connect: list[str] = field(default_factory=list)
    zenoh_listen: list[str] = field(default_factory=list)
    zenoh_mode: str = "client"
    manual_start: bool = False  # leave arming / OFFBOARD to the operator
    land_at: float | None = None  # mission time (s) of a coordinated land-all
    # HEARTBEAT period asked of the vehicle (s): how soon a third party's mode change is seen
    heartbeat_interval: float = 0.1
    signing_key: bytes | None = None  # MAVLink 2 signing of the vehicle link (32 bytes)
    # real time: land this long (s) after the last truth when the runner/router is lost
    # (offboard.daemon.runner_loss; 0 = hold until truth is back)
    loss_land_after: float = LAND_AFTER_S
    # fly without waiting for the swarm (offboard.daemon.mavlink.mode_requests.SwarmReady)
    solo: bool = False
    # the sensor's inputs (offboard.daemon.sensing_source)
    sensing: SensingSource = SensingSource.TRUTH
    # leave the vehicle's default telemetry on (offboard.daemon.mavlink.stream_trim)
    keep_streams: bool = False
    # real-time followers: the navigation check's gate (m, offboard.daemon.nav_check; 0 = no check)
    nav_gate_m: float = NAV_GATE_M
