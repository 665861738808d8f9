"""Safety filters: how a follower turns its nominal control into the applied one.

Entry point: :func:`offboard.safety.filter.make_filters` (one class per
:class:`swarm_common.enums.Method`, the table :data:`offboard.safety.filter.SAFETY_FILTERS`).

* :mod:`offboard.safety.base` - what every filter shares: its input, output and base class.
* :mod:`offboard.safety.dcbf` - the product's filter: a sampled-data CBF over the realisable
  input set (docs/safety.md); a follower runs it from its state in one compiled call
  (:mod:`offboard.safety.dcbf.front`).
* :mod:`offboard.safety.rcbf` - the paper's CLF-RCBF QP (kept for comparison).
* :mod:`offboard.safety.apf` - the improved APF baseline and no avoidance.
* :mod:`offboard.safety.solvers` - one adapter per QP solver (DAQP, OSQP).
* :mod:`offboard.safety.monitor` - the in-flight safety alarms (estimate residual, a neighbour
  heard too late) a follower raises beside its filter.
* :mod:`offboard.safety.pair_kernel`, :mod:`offboard.safety.clf_kernel`,
  :mod:`offboard.safety.qp_rows_kernel` - compiled terms every filter shares.
"""
