"""Safety filters: how a follower turns its nominal control into the applied one.

Entry point: :func:`offboard.safety.filter.make_filters` (one class per
:class:`swarm_common.enums.Method`).

* :mod:`offboard.safety.dcbf` - the product's filter: a sampled-data CBF over the realisable
  input set (docs/safety.md).
* :mod:`offboard.safety.rcbf` - the paper's CLF-RCBF QP (kept for comparison).
* :mod:`offboard.safety.apf` - the improved APF baseline and no avoidance.
* :mod:`offboard.safety.solvers` - one adapter per QP solver (DAQP, OSQP).
* :mod:`offboard.safety.pair_kernel`, :mod:`offboard.safety.clf_kernel`,
  :mod:`offboard.safety.qp_rows_kernel` - compiled terms every filter shares.
"""
