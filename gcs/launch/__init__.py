"""How a run's child processes begin.

* :mod:`.forkserver` - :func:`~gcs.launch.forkserver.start` forks ``python -m MODULE``
  from a preloaded server instead of starting an interpreter (``SWARM_LAUNCH=exec``
  turns it off); used by :class:`gcs.mission.procs.ProcessGroup`.
* :mod:`.preload` - what the server imports and loads once before it forks.
"""
