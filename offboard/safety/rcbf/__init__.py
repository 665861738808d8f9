"""``Method.RCBF``: the paper's CLF-RCBF quadratic program (paper §4.2-4.4).

Entry points: :class:`offboard.safety.rcbf.clf_rcbf.SafetyQP` and
:func:`offboard.safety.rcbf.clf_rcbf.clf_terms`; :mod:`.kernel` builds one step's rows.
"""
