"""The simulator's transports: MAVLink over UDP and ground truth on Zenoh.

* :class:`vehicle_sim.link.endpoint.MavlinkLink` - one non-blocking UDP endpoint.
* :mod:`.server_io` - the server's MAVLink reads and writes.
* :mod:`.truth` - one ``wire.Truth`` per control step.
"""
