"""``Method.RCBF``: the paper's CLF-RCBF quadratic program (paper §4.2-4.4).

Entry points: :class:`offboard.safety.rcbf.filter.RcbfFilter` (the filter),
:class:`offboard.safety.rcbf.clf_rcbf.SafetyQP` (its QP) and
:func:`offboard.safety.rcbf.clf_rcbf.clf_terms_of_reference` (the CLF terms and the nominal
control every method shares); :mod:`.kernel` builds one step's rows.
"""
