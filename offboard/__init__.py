"""``offboard``: the per-agent offboard controller (one daemon per agent, or packed).

Rooms, bottom up (each imports only the ones above it in this list, and ``swarm_common``):

* :mod:`offboard.records` - the records an agent exchanges (estimate, status, output).
* :mod:`offboard.estimation` - bearing geometry, synthetic sensing, the DESO, the
  desired-state observer and neighbour prediction.
* :mod:`offboard.inner_loop` - virtual control to attitude setpoint, and the inner-loop
  model that realises it.
* :mod:`offboard.safety` - the safety filters (``dcbf``, ``rcbf``, ``apf``, ``none``) and
  their QP solvers.
* :mod:`offboard.agent` - one agent's control step (:func:`offboard.agent.factory.make_agent`),
  shared by the in-process runner and the daemons; take-off, landing, governor.
* :mod:`offboard.daemon` - the process around an agent: MAVLink to its vehicle, Zenoh to
  the swarm, failsafes.

Entry points: the ``offboard`` command (:func:`offboard.cli.main`) and ``python -m offboard``.
"""
