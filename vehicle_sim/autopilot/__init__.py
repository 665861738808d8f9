"""One simulated PX4 vehicle's autopilot state, without sockets.

* :mod:`.modes` - flight modes, arming and transitions.
* :mod:`.setpoints`, :mod:`.setpoint_input` - offboard setpoints in, what the vehicle flies.
* :mod:`.nav`, :mod:`.nav_flight` - the AUTO modes' navigation targets.
* :mod:`.params`, :mod:`.param_defaults` - the PX4 parameters.
* :mod:`.telemetry`, :mod:`.streams` - the messages a vehicle sends and their schedule.
* :mod:`.mavlink_extra` - messages pymavlink's ``common`` dialect does not generate.
"""
