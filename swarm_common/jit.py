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
"What a control step costs"). So a loop writes into arrays made before it, and a row
computation called per row is written out in the loop instead.

A kernel takes and returns numpy arrays and floats only; the classes around it keep the
state, the validation and the names (docstrings of each kernel give units and equations).

**Call sites.** Calling a kernel through numba's dispatcher types every argument on every
call (a fingerprint per argument, then a search of the compiled signatures): 2.4 of the
10.8 µs of a dcbf front call with its 41 arrays. A hot call site whose arguments keep
their types, because they are the caller's own buffers or pass through the
``swarm_common.fastnp`` guards (float64, C order), holds a :class:`CallSite`: its first
call goes through the dispatcher (compiling if need be), and later calls go straight to
the compiled signature's entry point, which converts the arguments as that signature
says. An argument of another type there would be read as the first call's type, so only
such call sites use one. With ``$SWARM_JIT_CHECK=1`` every call checks the types against
the first call's and raises ``TypeError`` on a change (the unit tests run scenarios so).
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


CHECK_ENV = "SWARM_JIT_CHECK"


class CallSite:
    """One call site of ``kernel`` whose arguments keep their types from call to call
    (module docstring, "Call sites"): ``site.call(*args)`` instead of ``kernel(*args)``.
    Positional arguments only."""

    __slots__ = ("kernel", "call", "types", "_entry")

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.kernel = fn
        self.call: Callable[..., Any] = self._first
        self.types: tuple[Any, ...] | None = None  # the numba types of the first call
        self._entry: Callable[..., Any] | None = None

    def _first(self, *args: Any) -> Any:
        out = self.kernel(*args)  # typed, compiled if need be
        types = tuple(self.kernel.typeof_pyval(a) for a in args)  # type: ignore[attr-defined]
        compiled = self.kernel.overloads.get(types)  # type: ignore[attr-defined]
        if compiled is None:  # the dispatcher converted the arguments to another signature:
            self.call = self.kernel  # it keeps typing them, without typing them twice here
        else:
            self.types, self._entry = types, compiled.entry_point
            self.call = self._checked if os.environ.get(CHECK_ENV) == "1" else self._entry
        return out

    def _checked(self, *args: Any) -> Any:
        types = tuple(self.kernel.typeof_pyval(a) for a in args)  # type: ignore[attr-defined]
        if types != self.types:
            changed = [f"{i}: {a} -> {b}" for i, (a, b) in
                       enumerate(zip(self.types or (), types, strict=False)) if a != b]
            raise TypeError(f"{self.kernel.__name__}: argument types changed at a call "
                            f"site ({'; '.join(changed) or 'count'})")
        assert self._entry is not None
        return self._entry(*args)


def kernel(fn: F) -> F:
    """``fn`` compiled with the project's settings (module docstring)."""
    opts: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
    return cast(F, njit(**opts)(fn))
