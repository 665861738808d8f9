"""The formation's MAVLink vehicle served by the dashboard (``gcs dashboard --launch
SCENARIO --formation-vehicle``): QGroundControl, MAVProxy or MAVSDK fly the whole formation
as one PX4 vehicle while the dashboard watches it (docs/missions.md, "The formation as one
vehicle").

Entry point: :class:`FormationLink`, ticked on the app's event loop every
:data:`gcs.dashboard.app.FORMATION_TICK_S`. It feeds
:class:`gcs.formation.vehicle.FormationVehicle` the latest truth of the Zenoh feed at the
swarm's mission time and publishes the vehicle's commands through the feed. The vehicle
shares the dashboard's :class:`~gcs.formation.steer.FormationSteer`, so the keys ``n`` and
``g`` and the MAVLink client steer one copy of the leaders' timeline.
"""

from __future__ import annotations

import logging
from typing import Protocol

import numpy as np

from gcs.formation.steer import FormationSteer
from gcs.formation.vehicle import FormationVehicle
from swarm_common import wire
from swarm_common.scenario.spec import Scenario

log = logging.getLogger(__name__)


class Feed(Protocol):
    """What the link reads and publishes through (:class:`~gcs.dashboard.zenoh_feed.ZenohFeed`)."""

    truth: wire.Truth | None

    def mission_time(self) -> float | None: ...
    def publish(self, cmd: wire.Command) -> str: ...


class FormationLink:
    """The formation vehicle on UDP ``port`` (module docstring). Raises OSError when the
    port is busy."""

    def __init__(self, sc: Scenario, feed: Feed, steer: FormationSteer, port: int,
                 key: bytes | None = None) -> None:
        self.feed = feed
        self.vehicle = FormationVehicle(sc, self._publish, port, key=key, steer=steer)
        self.port = port

    def _publish(self, cmd: wire.Command) -> None:
        try:
            self.feed.publish(cmd)
        except (RuntimeError, ValueError) as exc:  # the session closed: the vehicle goes on
            log.warning("formation vehicle: %s not published: %s", cmd.kind, exc)

    def tick(self) -> None:
        """Serve the vehicle with the latest truth; silent until the swarm reports a
        mission time (no command before the daemons take them)."""
        t = self.feed.mission_time()
        truth = self.feed.truth
        if t is None or truth is None:
            self.vehicle.serve(0.0, None, None)
            return
        self.vehicle.serve(float(t), np.asarray(truth.p, dtype=float),
                           np.asarray(truth.v, dtype=float))

    def close(self) -> None:
        self.vehicle.close()
