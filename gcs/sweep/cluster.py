"""``gcs mission sweep --cluster tcp://HOST:PORT``: the sweep's runs as Dask tasks.

Imported only when ``--cluster`` is given (the local pool never imports Dask). Each run is
one pure task, :func:`run_task`: the scenario's text (read once by this client), method,
seed, duration and the ``--allow-*`` flags in, the CSV row out, so the workers need no
shared file system, only the same installed package. Before anything runs,
:func:`check_workers` compares every worker's :func:`environment` (this package's version,
a digest of its source, Python's and the numerical libraries' versions) with this client's
and refuses a sweep with a mismatched worker. A worker that dies mid-run has its task
re-run by the scheduler on another worker; the task key
``scenario-method-seed-<digest of the job>`` is unique, so a run is reported once.
See docs/sweeps.md.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import importlib.util
import logging
import platform
import time
from pathlib import Path
from typing import Any

from distributed import Client, Future, as_completed

from gcs.sweep.jobs import (
    Job,
    RowCallback,
    SweepInputError,
    crashed_row,
    parse_address,
    run_job,
)
from gcs.sweep.rows import SweepProgress

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S = 5.0  # the scheduler must answer within this
WORKER_WAIT_S = 30.0  # a scheduler without any worker is refused after this
CHECK_TRIES = 3  # environment checks before a difference is a mismatch
TASK_RETRIES = 2  # re-runs of a task that raised (a run's own failure is a row, not a raise)
PACKAGES = ("swarm_common", "vehicle_sim", "offboard", "gcs")
LIBRARIES = ("numpy", "scipy", "numba", "daqp", "osqp")


@functools.cache
def versions() -> dict[str, str]:
    """This package's, Python's and the numerical libraries' versions (once per process)."""
    env = {"bearing-swarm": _version("bearing-swarm"), "python": platform.python_version()}
    env.update({lib: _version(lib) for lib in LIBRARIES})
    return env


def environment() -> dict[str, str]:
    """What must match between the client and every worker for identical rows:
    :func:`versions` and a digest of this package's source files (path and bytes of every
    ``.py``, read now: about 0.1 s)."""
    digest = hashlib.sha256()
    for pkg in PACKAGES:
        spec = importlib.util.find_spec(pkg)
        for root in (spec.submodule_search_locations or []) if spec else []:
            for f in sorted(Path(root).rglob("*.py")):
                digest.update(f.relative_to(Path(root).parent).as_posix().encode())
                digest.update(f.read_bytes())
    return {**versions(), "source": digest.hexdigest()[:16]}


def _one_line(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".replace("\n", " ")[:200]


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def connect(address: str, timeout_s: float = CONNECT_TIMEOUT_S,
            worker_wait_s: float = WORKER_WAIT_S) -> Client:
    """A client of the scheduler at ``address`` with at least one worker, every worker
    checked (:func:`check_workers`); a one-line :class:`SweepInputError` otherwise."""
    address = parse_address(address)
    quiet = logging.getLogger("distributed")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)  # the one-line error below says it all
    try:
        client = Client(address, timeout=timeout_s)
    except Exception as exc:  # refused, timed out, or not a Dask scheduler at all
        raise SweepInputError(f"--cluster {address}: no Dask scheduler answers "
                              f"({_one_line(exc)})") from None
    finally:
        quiet.setLevel(level)
    try:
        client.wait_for_workers(1, timeout=worker_wait_s)
        check_workers(client, address)
    except BaseException as exc:
        client.close()
        if isinstance(exc, SweepInputError):
            raise
        if isinstance(exc, TimeoutError | OSError):
            raise SweepInputError(f"--cluster {address}: no worker joined the scheduler in "
                                  f"{worker_wait_s:g} s") from None
        raise
    return client


def check_workers(client: Client, address: str, tries: int = CHECK_TRIES) -> int:
    """The number of workers; :class:`SweepInputError` naming the first worker whose
    :func:`environment` differs from this client's. A difference is checked again
    ``tries`` times 1 s apart: a source file saved between the two reads is not a
    mismatch."""
    for attempt in range(tries):
        here = environment()
        try:
            theirs: dict[str, Any] = client.run(environment)
        except Exception as exc:  # a worker without this package cannot import environment
            raise SweepInputError(f"--cluster {address}: a worker cannot run this package "
                                  f"({type(exc).__name__}: {exc}); install it on every "
                                  "worker (docs/sweeps.md)") from None
        bad = [(w, k, env.get(k)) for w, env in sorted(theirs.items())
               for k in here if env.get(k) != here[k]]
        if not bad:
            return len(theirs)
        if attempt + 1 < tries:
            time.sleep(1.0)
    worker, key, value = bad[0]
    raise SweepInputError(f"--cluster {address}: worker {worker} has {key} {value}, this "
                          f"client {here[key]}; install the same version on every worker "
                          "(docs/sweeps.md)")


def task_key(job: Job) -> str:
    """``scenario-method-seed-<digest>``: unique per run; the digest of the scenario text,
    duration and flags keeps two different sweeps on one scheduler apart."""
    what = f"{job.text}\0{job.duration_s!r}\0{job.allow_infeasible}\0{job.allow_unsafe}"
    digest = hashlib.sha256(what.encode()).hexdigest()[:10]
    return f"{job.scenario}-{job.method}-{job.seed}-{digest}"


def run_task(job: Job, expect: dict[str, str]) -> dict[str, Any]:
    """The Dask task: :func:`gcs.sweep.jobs.run_job` on a worker whose :func:`versions`
    are ``expect`` (one that joined after the check with other versions gives a crashed
    row, never a silently different one)."""
    mine = versions()
    if mine != expect:
        k = next(k for k in expect if mine.get(k) != expect[k])
        return crashed_row(job, RuntimeError(f"worker has {k} {mine.get(k)}, client "
                                             f"{expect[k]}"))
    return run_job(job)


def run_cluster_sweep(
    client: Client, jobs: list[Job], on_row: RowCallback, show_progress: bool = True,
) -> int:
    """Submit every job, give each row to ``on_row`` as it arrives; the number of rows.
    A task whose workers all died (the scheduler's allowed failures) is a crashed row. On
    SIGINT/SIGTERM the pending tasks are cancelled before the exception propagates."""
    bar = SweepProgress([j.duration_s for j in jobs], show_progress)
    expect = versions()
    futs: dict[Future, Job] = {}
    seen: set[str] = set()
    try:
        for job in jobs:
            futs[client.submit(run_task, job, expect, key=task_key(job), pure=True,
                               retries=TASK_RETRIES)] = job
        for fut in as_completed(list(futs)):
            job = futs.pop(fut)
            if fut.key in seen:  # as_completed yields each future once; never count twice
                continue
            seen.add(fut.key)
            try:
                row = fut.result()
            except Exception as exc:  # KilledWorker, a lost scheduler
                log.error("run %s/%s/seed %d failed on the cluster: %s", job.scenario,
                          job.method, job.seed, exc)
                row = crashed_row(job, exc)
            fut.release()
            on_row(row)
            bar.add(job.duration_s, row["status"] == "ok")
    except BaseException:
        client.cancel(list(futs))
        raise
    finally:
        bar.close()
    return len(seen)
