"""One simulated PX4 vehicle's autopilot state, without sockets.

Entry point: :class:`vehicle_sim.autopilot.state.VehicleState` (the vehicle's state; the
functions below take one), set up by :class:`vehicle_sim.autopilot.config.AutopilotConfig`.

* :mod:`.state`, :mod:`.config` - the state and its helpers; the settings and default
  stream rates.
* :mod:`.modes` - flight modes, arming and transitions.
* :mod:`.setpoints`, :mod:`.setpoint_input` - offboard setpoints in, what the vehicle flies.
* :mod:`.nav`, :mod:`.nav_flight` - the AUTO modes' navigation targets.
* :mod:`.params`, :mod:`.param_defaults` - the PX4 parameters.
* :mod:`.telemetry`, :mod:`.streams` - the messages a vehicle sends and their schedule.
* :mod:`.mavlink_extra` - messages pymavlink's ``common`` dialect does not generate.
* :mod:`.audit` - the audit trail: every command the vehicle received, and its result.
"""
