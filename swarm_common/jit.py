"""Compiled kernels: the one place that sets how numba compiles the control core (issue 11).

Every kernel is ``@kernel``: numba's ``njit`` with

* ``cache=True``: compiled once per machine and source version and kept on disk (a
  daemon loads it in milliseconds instead of compiling it again);
* ``error_model="numpy"``: a division by zero gives inf or nan as numpy does, not an
  exception;
* no ``fastmath``: IEEE arithmetic, operations in the order written (no reassociation, no
  fused multiply-add), so a kernel gives the same bits in every process that loads it
  (in-process and distributed runs stay equal).

**Cache.** numba keys a kernel's cache by its own source file only: a kernel that calls a
kernel of another file (``attitude_kernel`` → ``frames_kernel``) would keep stale machine
code after that other file changed. The cache therefore lives in a folder named by a
fingerprint of every module that defines a kernel, ``<repository>/__pycache__/numba/<fp>``:
any change to any of them starts a fresh cache (a few seconds of compiling on the next
run). ``$NUMBA_CACHE_DIR``, when set, is used as it is.

**Loops and references.** numba counts references to arrays with atomic operations. An
array variable reassigned inside a loop (``a = np.concatenate(...)``), an array made or
viewed per iteration (``-(x * y)``, ``g[r]``), and a kernel inlined by numba into a loop
(``inline="always"``: each inlined array argument gets its own reference) count on every
iteration; at a thousand agents that was several per cent of a run (docs/performance.md,
"Past 255 agents"). So a loop writes into arrays made before it, and a row computation
called per row is written out in the loop instead.

A kernel takes and returns numpy arrays and floats only; the classes around it keep the
state, the validation and the names (docstrings of each kernel give units and equations).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import numba.core.config
from numba import njit

F = TypeVar("F", bound=Callable[..., Any])
PACKAGES = ("swarm_common", "vehicle_sim", "offboard", "gcs")
MARK = b"@kernel"


def kernel_sources_fingerprint(root: Path) -> str:
    """16 hex digits of SHA-256 over the path and text of every module under
    :data:`PACKAGES` that uses ``@kernel``."""
    h = hashlib.sha256()
    for pkg in PACKAGES:
        for f in sorted((root / pkg).rglob("*.py")):
            text = f.read_bytes()
            if MARK in text:
                h.update(f.relative_to(root).as_posix().encode())
                h.update(text)
    return h.hexdigest()[:16]


def _use_fingerprinted_cache() -> None:
    """Point numba's cache at ``<repository>/__pycache__/numba/<fingerprint>`` unless
    ``$NUMBA_CACHE_DIR`` is set or that folder cannot be made (numba's default then)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    root = Path(__file__).resolve().parents[1]
    folder = root / "__pycache__" / "numba" / kernel_sources_fingerprint(root)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    numba.core.config.CACHE_DIR = str(folder)  # type: ignore[attr-defined]  # set at run time


_use_fingerprinted_cache()


def kernel(fn: F) -> F:
    """``fn`` compiled with the project's settings (module docstring)."""
    opts: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
    return cast(F, njit(**opts)(fn))
