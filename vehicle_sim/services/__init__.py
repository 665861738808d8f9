"""The MAVLink services of a simulated vehicle, one module per service (as MAVSDK has
one plugin per service).

Entry point: :func:`vehicle_sim.services.registry.attach_services`.

* :mod:`.command` - COMMAND_LONG / COMMAND_INT.
* :mod:`.info` - PING, data-stream requests, capabilities and other connect-time requests.
* :mod:`.mission` - missions, geofence and rally points (:mod:`.mission_transfer`,
  :mod:`.mission_items`, :mod:`.mission_executor`, :mod:`.geofence`).
* :mod:`.param` - the parameter protocol.
"""
