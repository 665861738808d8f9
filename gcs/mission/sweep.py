"""``gcs mission sweep``: many in-process runs in parallel, one metrics row per run.

    gcs mission sweep SCENARIO... --seeds 1-100 --methods rcbf,apf,none --jobs N --out DIR
                      [--duration S]

Every (scenario, method, seed) is one :func:`gcs.mission.inproc.run_inproc` in a worker process
(:func:`worker_pool`: fresh ``spawn`` processes, ``--jobs`` of them, default
``os.cpu_count()``); progress on stderr (:mod:`gcs.mission.progress`, over the simulated seconds of
all runs). Writes ``DIR/runs.csv`` (:data:`gcs.report.sweep.CSV_COLUMNS`), ``DIR/summary.md``
and ``DIR/summary.png`` (:mod:`gcs.report.sweep`). A run that raises is kept as a row with
status ``crashed`` and its error. Bad input (scenario, seeds, methods, jobs, duration): one
line on stderr, exit 2.
"""

from __future__ import annotations

import argparse
import logging
import multiprocessing
import os
import sys
import time
import traceback
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs.exit_codes import EXIT_USAGE
from gcs.mission.progress import Progress
from gcs.report.sweep import flat_row, write_outputs
from swarm_common.enums import Method
from swarm_common.inputs import SEED_MAX, finite_float, out_dir_problem
from swarm_common.logsetup import configure_logging
from swarm_common.scenario.model import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    Scenario,
    ScenarioError,
    load_scenario,
)

log = logging.getLogger(__name__)


class SweepInputError(ValueError):
    """Bad command-line input of the sweep (exit 2); ``str()`` is the one-line reason."""


MAX_SWEEP_SEEDS = 100_000  # as gcs mission compare --seeds
MAX_SWEEP_JOBS = 256  # as gcs mission compare --jobs
MAX_SWEEP_DURATION_S = 3600.0  # as scenario.duration_s


@dataclass(frozen=True)
class Job:
    """One run of the sweep."""

    path: str  # scenario file
    scenario: str  # scenario name
    method: str
    seed: int
    duration_s: float
    allow_infeasible: bool = False  # --allow-infeasible: load the scenario with a warning
    allow_unsafe: bool = False  # --allow-unsafe: load it with a warning per broken assumption


def parse_seeds(text: str) -> list[int]:
    """``"1-100"`` (inclusive range) or ``"1,4,9"`` (list) → seeds ≥ 0, in order, no repeats."""
    text = text.strip()
    try:
        if "," not in text and "-" in text:
            lo_s, hi_s = text.split("-", 1)
            lo, hi = int(lo_s), int(hi_s)
            if lo > hi:
                raise SweepInputError(f"--seeds {text!r}: empty range ({lo} > {hi})")
            if hi - lo >= MAX_SWEEP_SEEDS:  # checked before the list is built
                raise SweepInputError(f"--seeds {text!r}: more than {MAX_SWEEP_SEEDS} seeds")
            seeds = list(range(lo, hi + 1))
        else:
            seeds = [int(s) for s in text.split(",")]
    except ValueError as exc:
        if isinstance(exc, SweepInputError):
            raise
        raise SweepInputError(
            f"--seeds {text!r}: expected a range like 1-100 or a list like 1,4,9"
        ) from None
    if any(not 0 <= s <= SEED_MAX for s in seeds):
        raise SweepInputError(f"--seeds {text!r}: seeds must be in 0..{SEED_MAX}")
    if len(seeds) > MAX_SWEEP_SEEDS:
        raise SweepInputError(f"--seeds {text!r}: more than {MAX_SWEEP_SEEDS} seeds")
    return list(dict.fromkeys(seeds))


def parse_methods(text: str) -> list[str]:
    """``"rcbf,apf,none"`` → the methods, each a :class:`~swarm_common.enums.Method`."""
    names = [m.strip() for m in text.split(",") if m.strip()]
    known = [str(m) for m in Method]
    bad = [m for m in names if m not in known]
    if bad or not names:
        raise SweepInputError(
            f"--methods {text!r}: unknown method {', '.join(bad) or '(none given)'}; "
            f"choose from {','.join(known)}"
        )
    return list(dict.fromkeys(names))


def parse_jobs(text: str | None) -> int:
    """``--jobs``: a positive integer; None → ``os.cpu_count()``."""
    if text is None:
        return os.cpu_count() or 1
    try:
        jobs = int(text)
    except ValueError:
        raise SweepInputError(f"--jobs {text!r}: not an integer") from None
    if not 1 <= jobs <= MAX_SWEEP_JOBS:
        raise SweepInputError(f"--jobs {text!r}: must be in 1..{MAX_SWEEP_JOBS}")
    return jobs


def parse_duration(text: str | None) -> float | None:
    """``--duration``: seconds > 0 and finite; None → each scenario's ``run.duration_s``."""
    if text is None:
        return None
    v = finite_float(text)
    if v is None or not 0 < v <= MAX_SWEEP_DURATION_S:
        raise SweepInputError(f"--duration {text!r}: must be a finite number of seconds in "
                              f"(0, {MAX_SWEEP_DURATION_S:g}]")
    return v


def load_all(
    paths: list[str], allow_infeasible: bool = False, allow_unsafe: bool = False
) -> list[tuple[str, Scenario]]:
    """Load every scenario file up front (a bad one is bad input, before any run)."""
    out = []
    for p in paths:
        try:
            out.append((p, load_scenario(p, allow_infeasible, allow_unsafe)))
        except ScenarioError as exc:
            raise SweepInputError(str(exc).replace("\n", " ")) from None
    return out


def make_jobs(
    scenarios: list[tuple[str, Scenario]], methods: list[str], seeds: list[int],
    duration: float | None,
) -> list[Job]:
    return [
        Job(p, sc.name, m, s, float(sc.run.duration_s if duration is None else duration),
            sc.allow_infeasible, sc.allow_unsafe)
        for p, sc in scenarios for m in methods for s in seeds
    ]


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` fresh interpreters (``spawn``), each logging as this process does.

    Never ``fork``: a caller with threads (a test runner's, a dashboard's, Zenoh's) may hold
    a lock at the moment of the fork, and the child then waits on it for ever."""
    level = logging.getLevelName(logging.getLogger().getEffectiveLevel()).lower()
    if level not in ("debug", "info", "warning", "error"):
        level = "warning"
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=configure_logging, initargs=(level,))


def run_job(job: Job) -> dict[str, Any]:
    """Worker: one in-process run → its CSV row; an exception becomes a ``crashed`` row
    (logged with its traceback in the worker)."""
    from gcs.mission.inproc import run_inproc

    base = {"scenario": job.scenario, "method": job.method, "seed": job.seed,
            "duration_s": job.duration_s}
    t0 = time.perf_counter()
    try:
        sc = load_scenario(job.path, job.allow_infeasible, job.allow_unsafe)
        res = run_inproc(sc, job.method, seed=job.seed, duration=job.duration_s)
    except Exception as exc:  # any failure of a run is logged and recorded, never lost
        log.error("run %s/%s/seed %d crashed:\n%s", job.scenario, job.method, job.seed,
                  traceback.format_exc())
        return {**base, "status": "crashed", "error": _one_line(exc),
                "wall_s": time.perf_counter() - t0}
    return {**base, "status": "ok", "error": "", **flat_row(res.metrics)}


def _one_line(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".replace("\n", " ")[:500]


def run_sweep(
    jobs: list[Job], workers: int, show_progress: bool = True,
    rows: list[dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """Run every job on ``workers`` processes; one row per finished job, appended to
    ``rows`` as it finishes (so an interrupted sweep keeps what ran). On SIGINT/SIGTERM
    (KeyboardInterrupt/SystemExit) the pending jobs are cancelled and the workers
    terminated before the exception propagates."""
    total = sum(j.duration_s for j in jobs)
    bar = Progress(total, label=f"sweep {len(jobs)} runs") if show_progress else None
    rows = [] if rows is None else rows
    done_s, crashed = 0.0, 0
    ex = worker_pool(workers)
    try:
        futs: dict[Future[dict[str, Any]], Job] = {ex.submit(run_job, j): j for j in jobs}
        for fut in as_completed(futs):
            job = futs[fut]
            try:
                row = fut.result()
            except BrokenProcessPool as exc:  # a worker died (killed, out of memory)
                row = {"scenario": job.scenario, "method": job.method, "seed": job.seed,
                       "duration_s": job.duration_s, "status": "crashed",
                       "error": _one_line(exc)}
            rows.append(row)
            crashed += row["status"] != "ok"
            done_s += job.duration_s
            if bar is not None:
                bar.update(done_s, f"{len(rows)}/{len(jobs)} runs, {crashed} crashed")
    except BaseException:
        procs = list(getattr(ex, "_processes", {}).values())
        ex.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        raise
    else:
        ex.shutdown(wait=True)
    finally:
        if bar is not None:
            bar.close()
    return rows


def cmd_mission_sweep(args: argparse.Namespace) -> int:
    """``gcs mission sweep``: exit 0 (even with crashed runs: they are in runs.csv), 2 on
    bad input."""
    try:
        seeds = parse_seeds(args.seeds)
        methods = parse_methods(args.methods)
        workers = parse_jobs(args.jobs)
        duration = parse_duration(args.duration)
        scenarios = load_all(args.scenario, args.allow_infeasible, args.allow_unsafe)
    except SweepInputError as exc:
        print(f"gcs mission sweep: {exc}", file=sys.stderr)
        return EXIT_USAGE
    out = Path(args.out or f"runs/sweep-{time.strftime('%Y%m%d-%H%M%S')}")
    if (why := out_dir_problem(out, "--out")) is not None:  # before any run starts
        print(f"gcs mission sweep: {why}", file=sys.stderr)
        return EXIT_USAGE
    jobs = make_jobs(scenarios, methods, seeds, duration)
    log.info("sweep: %d runs on %d workers -> %s", len(jobs), workers, out)
    t0 = time.monotonic()
    rows: list[dict[str, Any]] = []
    specs = {sc.name: sc for _, sc in scenarios}
    try:
        run_sweep(jobs, workers, rows=rows)
    except (KeyboardInterrupt, SystemExit):
        if rows:  # an interrupted sweep keeps the runs that finished
            write_outputs(out, rows, specs, methods, wall_s=time.monotonic() - t0)
            log.warning("interrupted: %d of %d runs written to %s", len(rows), len(jobs), out)
        raise
    write_outputs(out, rows, specs, methods, wall_s=time.monotonic() - t0)
    n_bad = sum(r["status"] != "ok" for r in rows)
    if n_bad:
        log.warning("%d of %d runs crashed (status 'crashed' in runs.csv)", n_bad, len(rows))
    log.info("wrote %s/runs.csv, summary.md, summary.png", out)
    return 0


def add_sweep_parser(msub: argparse._SubParsersAction) -> None:
    """Register ``gcs mission sweep`` (values validated by the command: one-line errors)."""
    s = msub.add_parser("sweep", help="many seeds x methods x scenarios in parallel")
    s.add_argument("scenario", nargs="+", help="scenario file(s)")
    s.add_argument("--seeds", default="1-20", help="range 1-100 or list 1,4,9 (default 1-20)")
    s.add_argument("--methods", default=",".join(str(m) for m in Method),
                   help="comma-separated methods (default: all)")
    s.add_argument("--jobs", default=None, help="worker processes (default: CPU count)")
    s.add_argument("--duration", default=None, help="seconds per run (default: scenario)")
    s.add_argument("--out", default=None, help="output directory (default runs/sweep-TIME)")
    s.add_argument(ALLOW_INFEASIBLE_FLAG, action="store_true",
                   help="run scenarios that fail the feasibility check, with a warning")
    s.add_argument(ALLOW_UNSAFE_FLAG, action="store_true",
                   help="run scenarios that break a load-time safety assumption, with a warning")
    s.set_defaults(func=cmd_mission_sweep)
