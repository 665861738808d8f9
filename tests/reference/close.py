"""How a compiled kernel is compared with its numpy reference formulation.

Two implementations of one formula (a numba kernel and numpy, or numpy's BLAS-backed
``@`` and a left-to-right loop) may round differently in the last bits: numpy and
OpenBLAS pick pairwise or SIMD summation orders by machine and thread count, and an
un-jitted kernel (``NUMBA_DISABLE_JIT=1``) runs in Python floats. Their answers are
therefore compared within a stated tolerance, never bit for bit; bit-for-bit checks are
kept for two runs of the same code.

* :data:`RTOL` / :data:`ATOL`: a few rounding errors of sums of a handful of O(1–100)
  terms. Relative 1e-12 is about 4500 ulp; absolute 1e-12 covers results that cancel to
  near zero, whose relative error is unbounded (e.g. −1.4416016383045448e-11 against
  −1.4416016383045447e-11 on one AMD EPYC machine).
"""

from __future__ import annotations

from typing import Any

import numpy as np

RTOL = 1e-12
ATOL = 1e-12


def assert_close(got: Any, want: Any, msg: object = "", rtol: float = RTOL,
                 atol: float = ATOL) -> None:
    """``got`` equals ``want`` within ``|got − want| ≤ atol + rtol·|want|`` element-wise,
    shapes equal, nan where the other is nan and infinities equal."""
    g, w = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    assert g.shape == w.shape, (msg, g.shape, w.shape)
    np.testing.assert_allclose(g, w, rtol=rtol, atol=atol, equal_nan=True, err_msg=str(msg))
