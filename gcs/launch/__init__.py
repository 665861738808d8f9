"""How a run's child processes begin.

* :mod:`.forkserver` - :func:`~gcs.launch.forkserver.start` forks ``python -m MODULE``
  from a preloaded server instead of starting an interpreter (``SWARM_LAUNCH=exec``
  turns it off); used by :class:`gcs.mission.procs.ProcessGroup`.
* :mod:`.preload` - what the server imports and loads once before it forks.
* :mod:`.watchdog` - folders removed however the runner ends (kill -9 included): a run's
  secrets (:func:`~gcs.launch.watchdog.remove_on_death`,
  :func:`~gcs.launch.watchdog.release_dir`) and the fork server's socket folder.
"""
