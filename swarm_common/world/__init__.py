"""The world around the swarm: static obstacles and the geofence (docs/world.md).

Entry points:

* :func:`swarm_common.world.config.parse_world`: the ``[[obstacle]]`` and ``[geofence]``
  tables of a scenario into a :class:`~swarm_common.world.config.World` (and back to TOML:
  :func:`~swarm_common.world.config.world_toml`);
* :func:`swarm_common.world.geometry.closest_point`: the closest surface point, outward
  normal and signed distance of one obstacle (compiled);
* :func:`swarm_common.world.geometry.world_planes`: the half-spaces an agent must stay in
  this step (what the dcbf filter turns into barrier rows);
* :func:`swarm_common.world.geometry.obstacle_distances` and
  :func:`~swarm_common.world.geometry.fence_margins`: the truth the verdict scores.

* :mod:`.config` - the ``[[obstacle]]`` and ``[geofence]`` tables: validation, typed view.
* :mod:`.geometry` - the compiled geometry: closest points, half-spaces, distances.
* :mod:`.geodesy` - the simulator's shared geodetic origin, latitude/longitude to ENU.
* :mod:`.mavlink_fence` - a fence as a vehicle stores it (MAVLink FENCE items) read back
  into a :class:`~swarm_common.world.config.Geofence` for the filter.
* :mod:`.mission_current` - MISSION_CURRENT with its ``fence_id``, which tells that a
  vehicle's fence changed.

The scenario's load-time check of its world is
:mod:`swarm_common.scenario.world_check`. All coordinates ENU, z up (m).
"""

__all__ = ["config", "geodesy", "geometry", "mavlink_fence", "mission_current"]
