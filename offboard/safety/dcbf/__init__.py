"""``Method.DCBF``: the sampled-data CBF safety filter (docs/safety.md).

Entry points: :class:`offboard.safety.dcbf.filter.DcbfFilter` (the QP, the lag tables and
the per-pair state) and :class:`offboard.safety.dcbf.front.DcbfFront` (a follower's step
from its state to the QP in one compiled call, the filter's only path in a follower).

* :mod:`.model` - the realisable input set and the inner-loop lag.
* :mod:`.qp` - the CLF + CBF QP over the input polytope.
* :mod:`.active_rows` - which kinds of rows were active at the QP's answer (the records').
* :mod:`.front` - the follower's step from its state to the QP in one compiled call.
* :mod:`.kernel`, :mod:`.step_kernel`, :mod:`.exact_kernel` - the compiled rows and steps
  (:mod:`.step_kernel` groups the rows' arguments in typed tuples).
"""
