"""The compiled products of the unmodeled-dynamics regressor (swarm_common.unmodeled):
Φ ζ and (Φᵀ e, ‖Φ‖_F²) against the matrix Φ that :func:`regressor` builds, on random
states (below the ground too), so the simulator's physics and the observer's model use
the one Φ."""

from __future__ import annotations

import numpy as np

from swarm_common.unmodeled import regressor
from swarm_common.unmodeled_kernel import regressor_t_times_kernel, unmodeled_accel_kernel


def test_products_equal_the_regressor_matrix() -> None:
    rng = np.random.default_rng(15)
    for trial in range(2000):
        p = rng.normal(0.0, 3.0, 3)
        v = rng.normal(0.0, 4.0, 3)
        zeta, e = rng.normal(0.0, 1.0, 6), rng.normal(0.0, 1.0, 3)
        h = float(rng.uniform(0.2, 2.0))
        phi = regressor(p, v, h)
        f = unmodeled_accel_kernel(p[2], v[0], v[1], v[2], zeta, h)
        assert np.allclose(f, phi @ zeta, rtol=1e-12, atol=1e-12), trial
        phte, fro2 = regressor_t_times_kernel(p[2], v[0], v[1], v[2], e, h)
        assert np.allclose(phte, phi.T @ e, rtol=1e-12, atol=1e-12), trial
        assert np.isclose(fro2, float((phi * phi).sum()), rtol=1e-12), trial
