"""Monte-Carlo sweeps: many in-process runs, on this machine or a Dask cluster.

Entry point: ``gcs mission sweep`` (:func:`gcs.sweep.cli.cmd_mission_sweep`).

* :mod:`.cli` - the command: inputs checked, runs dispatched, outputs written.
* :mod:`.jobs` - one run: the job, its parsers, the scenario from text, the run to its row.
* :mod:`.local` - the runs on local ``spawn`` worker processes.
* :mod:`.cluster` - the runs as Dask tasks (``--cluster``), workers' code checked first.
* :mod:`.rows` - ``runs.csv`` written as rows arrive, read back for ``--resume``; progress.
"""
