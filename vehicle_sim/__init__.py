"""``vehicle-sim``: a SITL-style simulator in which every drone is its own PX4-style vehicle.

Rooms, bottom up:

* :mod:`vehicle_sim.physics` - the swarm's dynamics and the vehicle's own controllers (pure).
* :mod:`vehicle_sim.autopilot` - one vehicle's PX4 state: modes, setpoints, navigation,
  parameters and telemetry.
* :mod:`vehicle_sim.services` - the MAVLink services a vehicle answers, one module each.
* :mod:`vehicle_sim.vehicle` - :class:`~vehicle_sim.vehicle.Vehicle`, the autopilot and its
  services behind one MAVLink message handler.
* :mod:`vehicle_sim.link` - MAVLink over UDP and ground truth on Zenoh.

Entry points: the ``vehicle-sim`` command (:func:`vehicle_sim.cli.main`) and
:class:`vehicle_sim.server.SimServer` (one select loop: dynamics, vehicles, clock, links).
"""
