"""Running a mission: in process or distributed (many runs: :mod:`gcs.sweep`).

Entry points:

* :func:`gcs.mission.inproc.run_inproc` - dynamics and every agent in one process, lockstep
  (or the agents in several: ``workers``).
* :func:`gcs.mission.distributed.run_and_score` - ``vehicle-sim``, a Zenoh router and one
  ``offboard`` daemon per agent (or packed) as real processes; :mod:`.recorder` records them
  and :mod:`.score` scores the record as the in-process runner would.

Support: :mod:`.launch_spec` (ports, endpoints and command lines), :mod:`.ports` (every
port a run binds, the probe, the free offset), :mod:`.preflight` (what a run checks
before it starts: the port offset, the physics, the formation's liveness), :mod:`.procs`
(child processes, the spawn worker pool), :mod:`.supervise` (the watch of a started
distributed run: a child's death, a stall, checkpoints), :mod:`.router`,
:mod:`.fault_flags`, :mod:`.progress`, :mod:`.run_output`,
:mod:`.run_logs` (what the children's logs say), :mod:`.warmup`,
:mod:`.run_cli` (the distributed ``gcs mission run``),
:mod:`.compare_cli` (``gcs mission compare``);
:mod:`.step_hooks` (the land-all sender and the formation vehicle, :mod:`gcs.formation`);
:mod:`.audit` (the commands a run received, for ``metrics.json``);
:mod:`.live_feed` (each runner's and the dashboard's rows for the live view,
:mod:`gcs.records.live`); :mod:`.agents` (an in-process run's agents in this process or
several, ``--workers``, and what crosses a wire, rounded as it does).
"""
