"""An in-process run's agents: stepped in its process or in several, and what they send.

Entry points:

* :func:`gcs.mission.agents.shards.agent_steppers` - the run's agents in ``workers``
  processes (:class:`~gcs.mission.agents.shards.LocalAgents` here,
  :class:`~gcs.mission.agents.shards.AgentShards` in several; ``--workers``:
  :func:`~gcs.mission.agents.shards.workers_for`);
* :mod:`gcs.mission.agents.wire_form` - what crosses a wire, rounded as the wire rounds
  it: the truth, the setpoints as the simulator decodes them, the published estimates.
"""

MAX_WORKERS = 64  # processes one in-process run may step its agents in (shards)
AUTO_WORKERS = "auto"  # --workers: as many as pay (shards.workers_for)
