"""Flying the whole formation from a ground station (docs/missions.md).

Entry points: :class:`~gcs.formation.vehicle.FormationVehicle` (system id 200, UDP 14560 +
offset), served by the distributed runner with ``gcs mission run --formation-vehicle``;
:class:`~gcs.formation.steer.FormationSteer`, the checked commands every ground-station side
(the vehicle, the dashboard's navigation menu) sends the leaders.

* :mod:`.vehicle` - the MAVLink endpoint: mission transfer, commands, ``FORM_SCALE``,
  heartbeat and the centroid's position; it publishes Zenoh ``mission``/``hold`` commands.
* :mod:`.steer` - go-to, step, scale, turn, hold and resume, checked on a replica of the
  leaders' mission timeline.
* :mod:`.translate` - mission items and commands as ``[mission]`` tables (pure).
"""
