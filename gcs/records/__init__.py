"""A run as a record that robotics tools open (issue 43; docs/records.md): an MCAP file for
Foxglove and PlotJuggler, CSV files per vehicle, written with the maintained ``mcap`` and
``foxglove-sdk`` packages.

* :mod:`.series` - the run's series with the safety filter's report (status, active rows,
  slacks, u_nom, ‖u − u_nom‖): what the record's QP topics carry.
* :mod:`.topics` - the topic scheme: topic and schema names, the ROS 2 message fields.
* :mod:`.payloads` - CDR bodies of the ROS 2 messages, every step at once (numpy).
* :mod:`.scene` - the ``/scene`` SceneUpdates: vehicles, bearings, obstacles, geofence.
* :mod:`.events` - the ``/events`` Log messages from metrics.json and the series.
* :mod:`.channels` - the record's channels and the messages of a step (file and live).
* :mod:`.writer` - :func:`~gcs.records.writer.write_record`: ``record.mcap`` of a run.
* :mod:`.live` - the live view: the same channels on a Foxglove WebSocket server.
* :mod:`.live_flags` - the live view's flags (``--foxglove``), light to import.
* :mod:`.reader` - read a record back: checks and the ROS 2 topics as arrays.
* :mod:`.export` - load a run folder or record; write the CSV files.
* :mod:`.layout` - the Foxglove layout shipped in docs/foxglove/.
* :mod:`.cli` - ``gcs log export`` (hook :func:`~gcs.records.cli.add_log_parser`).
"""
