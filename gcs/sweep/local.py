"""A sweep's runs on this machine: fresh ``spawn`` worker processes
(:func:`gcs.mission.procs.worker_pool`, ``--jobs`` of them), rows as they finish."""

from __future__ import annotations

import logging
from concurrent.futures import Future, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from gcs.mission.procs import worker_pool
from gcs.sweep.jobs import Job, RowCallback, crashed_row, run_job
from gcs.sweep.rows import SweepProgress

log = logging.getLogger(__name__)

def run_sweep(
    jobs: list[Job], workers: int, show_progress: bool = True,
    rows: list[dict[str, Any]] | None = None, on_row: RowCallback | None = None,
) -> list[dict[str, Any]]:
    """Run every job on ``workers`` processes; one row per finished job, appended to
    ``rows`` (and given to ``on_row``) as it finishes (so an interrupted sweep keeps what
    ran). On SIGINT/SIGTERM (KeyboardInterrupt/SystemExit) the pending jobs are cancelled
    and the workers terminated before the exception propagates."""
    bar = SweepProgress([j.duration_s for j in jobs], show_progress)
    rows = [] if rows is None else rows
    if not jobs:
        bar.close()
        return rows
    ex = worker_pool(workers)
    try:
        futs: dict[Future[dict[str, Any]], Job] = {ex.submit(run_job, j): j for j in jobs}
        for fut in as_completed(futs):
            job = futs[fut]
            try:
                row = fut.result()
            except BrokenProcessPool as exc:  # a worker died (killed, out of memory)
                row = crashed_row(job, exc)
            rows.append(row)
            if on_row is not None:
                on_row(row)
            bar.add(job.duration_s, row["status"] == "ok")
    except BaseException:
        procs = list(getattr(ex, "_processes", {}).values())
        ex.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        raise
    else:
        ex.shutdown(wait=True)
    finally:
        bar.close()
    return rows


