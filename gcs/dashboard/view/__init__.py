"""What the dashboard shows, computed from its feeds: plain data, no Textual, no sockets.

* :mod:`.state` - the snapshot the UI draws (:class:`~.state.SwarmView`, its rows and
  :class:`~.state.DashEvent`), built by :class:`~.state.LiveSource` from the MAVLink and
  Zenoh feeds; :mod:`.recorded` - a fixed, deterministic view (snapshots, docs).
* :mod:`.timeline` - one sim clock for every time on screen, and a repeated event shown
  once with its count.
* :mod:`.preflight` - the plan's envelope and whether the vehicles' parameters agree.
* :mod:`.mission_progress` - where a formation mission stands, and the typed go-to's parser.
* :mod:`.world_cells` - the scenario's obstacles and geofence as a view's character cells.
* :mod:`.replay` - a replay's clock over a recorded series (frame, speed, closest approach,
  events); :mod:`.replay_source` - a recorded run (run folder or record.mcap) as the source.
"""
