"""A tiny synthetic comparison for the report's tests (gcs.report): four vehicles, leaders
0 and 1 at 4 m apart, followers 2 and 3 closing to a chosen distance at a chosen time,
flown by three methods. Shared by tests/unit/gcs/test_report.py and test_report_failed.py."""

from __future__ import annotations

import numpy as np

D_SAFE = 0.5
FOLLOWERS = [2, 3]
EDGES = [(0, 1), (0, 2), (1, 3), (2, 3)]
# each method's closest approach of the followers, (t s, d m), and its ∫Σ‖u‖²dt
DIPS = {"rcbf": (2.0, 0.8), "apf": (1.5, 0.2), "none": (1.0, 0.1)}
ENERGY_U = {"rcbf": 300.0, "apf": 900.0, "none": 200.0}


def closing_series(dip_t: float, dip_d: float, n: int = 60, dt: float = 0.1) -> dict:
    """4 vehicles (leaders 0, 1 at 4 m apart; followers 2, 3) whose followers close to
    ``dip_d`` m at ``dip_t`` s; ``n`` samples ``dt`` s apart."""
    t = np.arange(n) * dt
    p = np.zeros((n, 4, 3))
    p[:, 0] = (0.0, 0.0, 5.0)
    p[:, 1] = (4.0, 0.0, 5.0)
    gap = 2.0 - (2.0 - dip_d) * np.exp(-(((t - dip_t) / 0.3) ** 2))
    p[:, 2] = np.stack([2.0 - gap / 2, np.full(n, 3.0), np.full(n, 5.0)], axis=1)
    p[:, 3] = np.stack([2.0 + gap / 2, np.full(n, 3.0), np.full(n, 5.0)], axis=1)
    zeros = np.zeros_like(p)
    return {
        "t": t,
        "p": p,
        "v": zeros,
        "p_des": p + 0.01,
        "z1": p,
        "z2": zeros,
        "lumped_est": zeros,
        "lumped_true": zeros + 0.01,
        "min_dist": np.minimum(gap, 4.0),
    }


def three_methods() -> dict[str, dict]:
    """rcbf, apf and none (in that order), each closing as :data:`DIPS` says."""
    return {m: closing_series(t, d) for m, (t, d) in DIPS.items()}
