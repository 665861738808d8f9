"""The offboard daemon: the process that flies one agent (or several, packed).

Entry points: :class:`offboard.daemon.core.OffboardDaemon` (one agent),
:class:`offboard.daemon.host.DaemonHost` (``offboard --agents 3-8``),
:class:`offboard.daemon.config.DaemonConfig` (its typed configuration).

Read top-down: :mod:`.core` (the process: links, modes, main loop) builds
:class:`offboard.daemon.loop.AgentLoop` (the agent's step and what it sends), which talks to
its links through :mod:`.ports` and leaves lockstep and real time to the two drivers of
:mod:`.drivers`.

* :mod:`offboard.daemon.mavlink` - the link to the agent's own vehicle.
* :mod:`offboard.daemon.zenoh` - the link to the swarm.
* :mod:`.commands` - ground-station commands (a handler per ``CommandKind``);
  :mod:`.stream` - the setpoint stream and the estimate re-sends.
* :mod:`.runner_loss`, :mod:`.nav_check` - failsafes of a real-time daemon;
  :mod:`.limits` - their defaults and bounds, as the command line shows them.
* :mod:`.sensing_source` - the sensor's inputs (truth or the swarm's odometry).
* :mod:`.link_guard` - pure guards of both links; :mod:`.wire_convert` - records to payloads.
* :mod:`.start_gate`, :mod:`.warmup`, :mod:`.output_burst`, :mod:`.packing` - start-up and
  packed processes.
"""
