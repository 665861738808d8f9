"""The offboard daemon's configuration (``offboard`` command line -> :class:`DaemonConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from offboard.nav_check import NAV_GATE_M
from offboard.runner_loss import LAND_AFTER_S
from swarm_common.enums import Method, SensingSource
from swarm_common.scenario import Scenario


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
    # (offboard.runner_loss; 0 = hold until truth is back)
    loss_land_after: float = LAND_AFTER_S
    solo: bool = False  # fly without waiting for the swarm (offboard.mode_requests.SwarmReady)
    sensing: SensingSource = SensingSource.TRUTH  # the sensor's inputs (offboard.sensing_source)
    keep_streams: bool = False  # leave the vehicle's default telemetry on (offboard.stream_trim)
    # real-time followers: the navigation check's gate (m, offboard.nav_check; 0 = no check)
    nav_gate_m: float = NAV_GATE_M
