"""What the daemon's agent loop needs of its two links: the small interface between the
loop (the agent's step, what it publishes, what it sends its vehicle) and the transport.

* :class:`VehiclePort` - the agent's own vehicle, over MAVLink
  (:class:`offboard.daemon.mavlink.link.VehicleLink`): its latest ODOMETRY and mode, and
  the attitude setpoint sent to it.
* :class:`SwarmPort` - the swarm, over Zenoh (:class:`offboard.daemon.zenoh.link.SwarmBus`):
  the neighbours' estimates in, ground-station commands in, our estimate, status and
  odometry out.

The process around the loop (:class:`offboard.daemon.core.OffboardDaemon`) keeps the
links' own life: opening, polling, heartbeats, the vehicle's commands, closing. Anything
with these members drives the loop (a test double, another transport).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Protocol, SupportsFloat

from offboard.daemon.mavlink.odometry import Odometry
from swarm_common import wire


class VehiclePort(Protocol):
    """The agent's own vehicle as the loop sees it."""

    @property
    def odometry(self) -> Odometry | None:
        """The vehicle's latest accepted ODOMETRY (its clock and measured state)."""
        ...

    @property
    def armed(self) -> bool: ...

    @property
    def in_offboard(self) -> bool: ...

    @property
    def offboard_reported(self) -> bool:
        """The vehicle has been in OFFBOARD at least once (latched)."""
        ...

    @property
    def custom_mode(self) -> int: ...

    def send_attitude_target(
        self, time_boot_ms: int, q_wxyz: Iterable[SupportsFloat], thrust_norm: SupportsFloat
    ) -> None:
        """SET_ATTITUDE_TARGET: NED/FRD quaternion w,x,y,z and normalised thrust."""
        ...


class SwarmPort(Protocol):
    """The swarm as the loop sees it."""

    @property
    def estimates(self) -> Mapping[int, dict[int, wire.Estimate]]:
        """Received estimates: step -> sender id -> estimate."""
        ...

    @property
    def latest_estimate(self) -> dict[int, wire.Estimate]:
        """Each sender's newest estimate."""
        ...

    @property
    def heard(self) -> set[int]:
        """Agents ever heard from (the swarm's readiness)."""
        ...

    @property
    def odometry_matched(self) -> bool:
        """Someone subscribes to our odometry."""
        ...

    def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Pump the received data until ``predicate()`` or ``timeout`` s; its last value."""
        ...

    def estimates_at(self, step: int) -> dict[int, wire.Estimate]: ...

    def set_reference(self, step: int) -> None:
        """The vehicle's current step (the reference of the payload guard)."""
        ...

    def end_readiness(self) -> None: ...

    def pop_commands(self) -> list[wire.Command]: ...

    def publish_estimate(self, est: wire.Estimate) -> None: ...

    def publish_status(self, status: wire.Status) -> None: ...

    def publish_odometry(self, odo: wire.Odometry) -> None: ...
