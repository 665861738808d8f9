"""One adapter per QP solver, in the way qpsolvers has one per solver.

* :mod:`.daqp_call` - DAQP's dual active-set solve (the default).
* :mod:`.osqp_call` - OSQP's update + solve without the wrapper's bookkeeping.

Both answer the same problems (tests/unit/safety/test_qp_solvers.py).
"""
