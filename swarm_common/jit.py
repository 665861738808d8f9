"""Compiled kernels: the one place that sets how numba compiles the control core (issue 11).

Every kernel is ``@kernel``: numba's ``njit`` with

* ``cache=True``: compiled once per machine and source version, kept in ``__pycache__``
  (a daemon loads it in milliseconds instead of compiling it again);
* ``error_model="numpy"``: a division by zero gives inf or nan as numpy does, not an
  exception;
* no ``fastmath``: IEEE arithmetic, operations in the order written (no reassociation, no
  fused multiply-add), so a kernel gives the same bits in every process that loads it
  (in-process and distributed runs stay equal).

A kernel takes and returns numpy arrays and floats only; the classes around it keep the
state, the validation and the names (docstrings of each kernel give units and equations).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

from numba import njit

F = TypeVar("F", bound=Callable[..., Any])


def kernel(fn: F) -> F:
    """``fn`` compiled with the project's settings (module docstring)."""
    return cast(F, njit(cache=True, nogil=True, error_model="numpy")(fn))
