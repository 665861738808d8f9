"""``Method.DCBF``: the sampled-data CBF safety filter (docs/safety.md).

Entry point: :class:`offboard.safety.dcbf.filter.DcbfFilter`.

* :mod:`.model` - the realisable input set, the inner-loop lag and the barrier rows.
* :mod:`.qp` - the CLF + CBF QP over the input polytope.
* :mod:`.front` - the follower's step from its state to the QP in one compiled call.
* :mod:`.kernel`, :mod:`.step_kernel`, :mod:`.exact_kernel` - the compiled rows and steps.
"""
