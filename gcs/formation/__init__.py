"""The formation as one MAVLink vehicle for every ground station (docs/missions.md).

Entry points: :class:`~gcs.formation.vehicle.FormationVehicle` (system id 200, UDP 14560 +
offset), served by the distributed runner with ``gcs mission run --formation-vehicle``.

* :mod:`.vehicle` - the MAVLink endpoint: mission transfer, commands, ``FORM_SCALE``,
  heartbeat and the centroid's position; it publishes Zenoh ``mission``/``hold`` commands.
* :mod:`.translate` - mission items and commands as ``[mission]`` tables (pure).
"""
