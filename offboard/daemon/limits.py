"""The real-time failsafes' defaults and bounds that ``offboard``'s flags show
(``--nav-gate``, ``--loss-land-after``), apart from the failsafes themselves
(:mod:`offboard.daemon.nav_check`, :mod:`offboard.daemon.runner_loss`): the command line
builds its parser from this module alone, so a bad flag or file is refused before the
daemon's numpy, numba, Zenoh and pymavlink load.
"""

from __future__ import annotations

NAV_GATE_M = 2.0  # m, |estimate − odometry| above this is a disagreement ...
NAV_GATE_STEPS = 3  # ... at this many consecutive checks: the estimate has diverged
MIN_NAV_GATE_M, MAX_NAV_GATE_M = 0.001, 1000.0  # m: the gates `offboard --nav-gate` takes
LAND_AFTER_S = 3.0  # s after the last truth: the default land time t_L − t_s
MIN_LAND_AFTER_S = 2.0  # s: lost (0.2 s) + settling in the hold + the landing's lead (1 s)
