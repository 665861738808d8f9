"""The leader's velocity ESO (offboard.agent.leader.velocity_eso_kernel) against the numpy
formulation it replaced: the same estimates within rounding (tests/reference/close.py: two
implementations) on random states and sub-step counts, and the
observer converging on a constant disturbance (so the test could fail on wrong gains)."""

from __future__ import annotations

import numpy as np
from reference.close import assert_close

from offboard.agent.leader import velocity_eso_kernel


def eso_numpy(v: np.ndarray, v_hat: np.ndarray, d_hat: np.ndarray, u_sub: np.ndarray,
              dl: float, l1: float, l2: float) -> tuple[np.ndarray, np.ndarray]:
    for s in range(len(u_sub)):
        err = v - v_hat
        v_hat = v_hat + dl * (u_sub[s] + d_hat + l1 * err)
        d_hat = d_hat + dl * l2 * err
    return v_hat, d_hat


def eso_kernel(*args: object) -> tuple[np.ndarray, np.ndarray]:
    """The kernel into a new (2,3) array (NaN first: every element must be written)."""
    out = np.full((2, 3), np.nan)
    velocity_eso_kernel(*args, out)
    return out[0], out[1]


def test_kernel_equals_the_numpy_formulation() -> None:
    rng = np.random.default_rng(4)
    for _ in range(300):
        n_sub = int(rng.integers(1, 12))
        args = (rng.normal(0, 2, 3), rng.normal(0, 2, 3), rng.normal(0, 1, 3),
                rng.normal(0, 3, (n_sub, 3)), 0.02 / n_sub, 10.0, 25.0)
        got = eso_kernel(*args)
        want = eso_numpy(*args)
        assert_close(got[0], want[0])
        assert_close(got[1], want[1])


def test_disturbance_estimate_converges() -> None:
    """True velocity v' = u + d with d constant: d̂ → d within a few seconds (poles −5)."""
    d = np.array([0.7, -0.4, 1.2])
    v, v_hat, d_hat = np.zeros(3), np.zeros(3), np.zeros(3)
    dt, n_sub = 0.02, 4
    u_sub = np.tile([0.5, 0.0, -0.3], (n_sub, 1))
    for _ in range(300):  # 6 s
        v_hat, d_hat = eso_kernel(v, v_hat, d_hat, u_sub, dt / n_sub, 10.0, 25.0)
        v = v + dt * (u_sub[0] + d)
    assert np.allclose(d_hat, d, atol=1e-3)
