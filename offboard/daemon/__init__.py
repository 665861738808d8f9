"""The offboard daemon: the process that flies one agent (or several, packed).

Entry points: :class:`offboard.daemon.core.OffboardDaemon` (one agent),
:class:`offboard.daemon.host.DaemonHost` (``offboard --agents 3-8``),
:class:`offboard.daemon.config.DaemonConfig` (its typed configuration).

* :mod:`offboard.daemon.mavlink` - the link to the agent's own vehicle.
* :mod:`offboard.daemon.zenoh` - the link to the swarm.
* :mod:`.commands` - ground-station commands; :mod:`.stream` - the setpoint stream.
* :mod:`.runner_loss`, :mod:`.nav_check` - failsafes of a real-time daemon.
* :mod:`.link_guard` - pure guards of both links; :mod:`.wire_convert` - records to payloads.
* :mod:`.start_gate`, :mod:`.warmup`, :mod:`.output_burst`, :mod:`.packing` - start-up and
  packed processes.
"""
