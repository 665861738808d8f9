"""numpy entry points for the per-step hot paths, without the Python wrappers' dispatch.

The control step is dozens of numpy calls on 3-vectors and (M,3) arrays, where the
Python-level wrapper of a function costs as much as its C loop. Each helper here calls
the very C routine the public function ends in, with the same arguments, so results are
the same bit for bit (docs/performance.md, issue 11):

* :func:`einsum` is the C ``c_einsum`` that ``np.einsum(..., optimize=False)`` (the
  default) forwards to: ≈ 1.2 µs instead of ≈ 1.9 µs for ``"ij,ij->i"`` on (7,3);
* :func:`norm` is ``np.linalg.norm(x)`` of a 1-D float64 vector: ``sqrt(x.dot(x))``
  (the same BLAS dot), as a float: ≈ 0.4 µs instead of ≈ 1.2 µs.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from typing import Any

import numpy as np


def _c_einsum() -> Callable[..., Any]:
    """numpy's C einsum (numpy ≥ 2: ``numpy._core``; 1.26: ``numpy.core``), else np.einsum."""
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            f = getattr(importlib.import_module(name), "c_einsum", None)
        except ImportError:  # pragma: no cover - the other numpy major version
            continue
        if callable(f):
            return f
    return np.einsum  # pragma: no cover


einsum: Callable[..., Any] = _c_einsum()

# the native float64 dtype: compared with ``==`` (not ``is``: the arrays a compiled kernel
# returns carry an equal dtype object of their own), ≈ 40 ns against ≈ 80 ns for
# ``== np.float64``, which converts the scalar type first
_F64 = np.dtype(np.float64)
_BOOL = np.dtype(np.bool_)
# numpy's C function, given the dtype instance as a positional argument: ≈ 55 ns against
# ≈ 95 ns for ``np.ascontiguousarray(x, dtype=np.float64)``, which parses a keyword and
# converts the scalar type to its dtype on every call (the same array either way)
_contiguous = np.ascontiguousarray
_VEC3_SHAPE, _VEC3_STRIDES = (3,), (8,)
_ROWS3_STRIDES = (24, 8)


def norm(x: np.ndarray) -> float:
    """``float(np.linalg.norm(x))`` for a 1-D float64 array (same dot, same sqrt)."""
    return math.sqrt(float(x.dot(x)))


def rows3(x: np.ndarray) -> np.ndarray:
    """``x`` as a C-contiguous float64 (M,3) array for a compiled kernel (the same array,
    no copy, when it already is one: float64 with strides (24, 8), i.e. C order; any
    other layout, a byte-swapped dtype included, takes the converting path)."""
    if x.dtype == _F64 and x.strides == _ROWS3_STRIDES and x.ndim == 2:
        return x
    return _contiguous(x, _F64).reshape(-1, 3)


def f64(x: np.ndarray) -> np.ndarray:
    """``x`` as a C-contiguous float64 array, the one layout a compiled kernel is compiled
    for (``x`` itself when it is one already)."""
    return _contiguous(x, _F64)


def bools(x: np.ndarray) -> np.ndarray:
    """``x`` as a C-contiguous bool array for a compiled kernel (``x`` itself when it is
    one already), through the same cheap call as :func:`f64`."""
    return _contiguous(x, _BOOL)


def vec3(x: np.ndarray) -> np.ndarray:
    """``x`` as a C-contiguous float64 (3,) array for a compiled kernel (the same array,
    no copy, when it already is one: native float64, shape (3,), stride 8; plain
    attribute compares, cheaper than ``x.flags``; a list or tuple is converted)."""
    try:
        if x.dtype == _F64 and x.shape == _VEC3_SHAPE and x.strides == _VEC3_STRIDES:
            return x
    except AttributeError:  # not an array: converted below
        pass
    return _contiguous(x, _F64).reshape(3)


def finite(x: np.ndarray) -> bool:
    """``bool(np.isfinite(x).all())`` for a short float array (a control vector, a QP's
    few variables): ≈ 0.2 µs instead of ≈ 1 µs (numpy's ``all`` is a Python-level
    wrapper). Python-level per element, so it is the slower one beyond a few dozen."""
    return all(map(math.isfinite, (x if x.ndim == 1 else x.ravel()).tolist()))
