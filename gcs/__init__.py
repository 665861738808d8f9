"""``gcs``: the ground station - mission runs, reports, sweeps and the dashboard.

Rooms, bottom up:

* :mod:`gcs.report` - metrics of a run and the reports written from them.
* :mod:`gcs.mission` - running a mission: in process, distributed (one process per
  vehicle and daemon), or as a sweep.
* :mod:`gcs.dashboard` - the Textual terminal dashboard.

Entry point: the ``gcs`` command (:func:`gcs.cli.main`); :mod:`gcs.keys` (signing keys) and
:mod:`gcs.scenario_gen` (generated formations) are its small sub-commands.
"""
