"""One BLAS thread for the in-process control loops.

Every matrix here is tiny (2×2 to 24×24: the exact DESO / reference / predictor
propagators built with ``scipy.linalg.expm`` on a new neighbour set or prediction age,
and numpy's small products), so OpenBLAS's worker threads never help; on a loaded
machine waking them costs milliseconds per call. Measured in an in-process cube8 dcbf run
at load average 8 on the 2-core machine: ``expm`` of the 12×12 exosystem matrix 6 ms
median with the default two BLAS threads, 75 µs with one. The distributed children get
the same through ``OPENBLAS_NUM_THREADS=1`` (gcs.mission.procs), and ``offboard`` and
``vehicle-sim`` started any other way (by hand, by a test) limit themselves at start; a
process that has already loaded numpy and scipy needs threadpoolctl for that. Results
are unchanged: OpenBLAS splits its work by output block, so each element is summed in
the same order (checked bit for bit
on the nine reference runs, docs/performance.md).
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits


def single_thread_blas() -> threadpool_limits:
    """Limit the loaded BLAS libraries (numpy's and scipy's OpenBLAS) to one thread until
    the returned context exits (or its ``restore_original_limits()`` is called)."""
    return threadpool_limits(limits=1, user_api="blas")
