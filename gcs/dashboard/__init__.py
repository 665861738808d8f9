"""``gcs dashboard``: a terminal ground-control station (Textual) for the swarm.

Modules, from the wire up (only ``app``, ``replay_app`` and ``widgets`` import Textual):

* :mod:`.px4modes` - PX4 custom-mode decoding and the COMMAND_LONG recipes.
* :mod:`.mavlink_gcs` - the MAVLink GCS link (UDP 14550+offset), per-system tracking,
  commands with COMMAND_ACK, timeout and retry.
* :mod:`.zenoh_feed` - truth / status / estimate subscriber, command publisher.
* :mod:`.zenoh_commands` - the UI's Zenoh commands published through the commander, each
  logged in the event log.
* :mod:`.view` - what is shown, as plain data: the snapshot (:mod:`.view.state`), one sim
  clock and merged repeats (:mod:`.view.timeline`), the pre-flight checks
  (:mod:`.view.preflight`), the mission's progress (:mod:`.view.mission_progress`), the
  world's cells (:mod:`.view.world_cells`), a recorded fixture (:mod:`.view.recorded`).
* :mod:`.navigate` - the navigation menu (``n``) and go-to (``g``) commands;
  :mod:`.group_commands` - commands for several vehicles (confirmation listing the
  targets, the coordinated take-off and land-all).
* :mod:`.formation_link` - the formation as one MAVLink vehicle, served by the dashboard.
* :mod:`.app`, :mod:`.widgets`, :mod:`.palette` - the Textual UI and its command palette;
  :mod:`.cli` - argument parsing, launch.
* :mod:`.replay_app` - ``--replay RUN``: the same UI on a recorded run (:mod:`.view.replay`).
"""
