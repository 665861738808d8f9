"""``gcs dashboard``: a terminal ground-control station (Textual) for the swarm.

Modules, from the wire up (only ``app`` and ``widgets`` import Textual):

* :mod:`.px4modes` - PX4 custom-mode decoding and the COMMAND_LONG recipes.
* :mod:`.mavlink_gcs` - the MAVLink GCS link (UDP 14550+offset), per-system tracking,
  commands with COMMAND_ACK, timeout and retry.
* :mod:`.zenoh_feed` - truth / status / estimate subscriber, command publisher.
* :mod:`.state` - the plain snapshot the UI draws (:class:`SwarmView`), built from the
  two feeds or from a recorded fixture; :mod:`.timeline` - one sim clock for every time on
  screen, and a repeated event shown once with its count.
* :mod:`.mission_progress` - where a formation mission stands (next waypoint, time to
  arrive, fraction done, planned centroid path) and the typed go-to's parser;
  :mod:`.navigate` - the navigation menu (``n``) and go-to (``g``) commands;
  :mod:`.group_commands` - commands for several vehicles (confirmation listing the
  targets, the coordinated take-off and land-all).
* :mod:`.world_cells` - the scenario's obstacles and geofence as a view's character cells.
* :mod:`.preflight` - the plan's envelope (altitude, closest pair, speed) and whether the
  vehicles' parameters agree, shown before take-off.
* :mod:`.formation_link` - the formation as one MAVLink vehicle, served by the dashboard.
* :mod:`.app`, :mod:`.widgets`, :mod:`.palette` - the Textual UI and its command palette;
  :mod:`.cli` - argument parsing, launch.
"""
