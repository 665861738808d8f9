"""``gcs mission compare SCENARIO``: every method on one scenario, in process or
distributed, then the comparison report (:mod:`gcs.report.comparison`) and, with
``--seeds N``, an in-process seed sweep. Exit codes: :mod:`gcs.exit_codes`."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from gcs.exit_codes import EXIT_OK, EXIT_RUN_FAILED, EXIT_USAGE
from swarm_common.enums import Method
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

METHODS = [str(m) for m in Method]
Outcome = tuple[dict[str, Any], dict[str, Any], list[str]]  # metrics, series, gains


def _run_one(job: tuple[str, bool, bool, str, int, float | None]) -> dict[str, Any]:
    from gcs.mission.inproc import run_inproc
    from swarm_common.scenario.model import load_scenario

    path, allow_infeasible, allow_unsafe, method, seed, duration = job
    sc = load_scenario(path, allow_infeasible, allow_unsafe)
    return run_inproc(sc, method, seed=seed, duration=duration).metrics


def _gain_lines(sc: Scenario) -> list[str]:
    from offboard.agent.factory import FollowerAgent, make_agent

    ag = make_agent(sc, sc.follower_ids[0])
    return ag.gains.lines() if isinstance(ag, FollowerAgent) else []


def _note_failed(failed: dict[str, tuple[str, int]], method: str, exc: Exception,
                 code: int) -> None:
    """Say a method's failed run in one line on stderr and keep its reason and exit code in
    ``failed`` (the report marks it; the command exits with the first such code)."""
    line = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    print(f"gcs mission compare: {method}: {line}", file=sys.stderr)
    failed[method] = (line, code)


def _compare_inproc(
    sc: Scenario, args: argparse.Namespace, out: Path, failed: dict[str, tuple[str, int]],
) -> Outcome | int:
    """Every method's in-process run. A method whose run fails (a worker of ``--workers``
    that died or raised: :class:`~gcs.mission.agents.shards.ShardError`) is left out of
    the outcome and put in ``failed`` with its one-line reason and exit code 1, as a
    distributed run's, and the others still run. Exit code 1 when no method finished."""
    from gcs.mission.agents import AUTO_WORKERS
    from gcs.mission.agents.shards import ShardError, workers_for
    from gcs.mission.inproc import run_inproc

    metrics: dict[str, Any] = {}
    series: dict[str, Any] = {}
    gains: list[str] = []
    workers = workers_for(getattr(args, "workers", AUTO_WORKERS), sc.n)
    for m in METHODS:
        log.info("running %s in process ...", m)
        try:
            res = run_inproc(sc, m, seed=args.seed, duration=args.duration, progress=False,
                             workers=workers)
        except ShardError as exc:  # the worker's traceback is in the log already
            _note_failed(failed, m, exc, EXIT_RUN_FAILED)
            continue
        res.save(out / m, sc)
        metrics[m], series[m], gains = res.metrics, res.series.as_dict(), res.gains
    if not metrics:
        return EXIT_RUN_FAILED
    return metrics, series, gains


def _compare_distributed(
    sc: Scenario, args: argparse.Namespace, out: Path, failed: dict[str, tuple[str, int]],
) -> Outcome | int:
    """Every method's distributed run. A method that fails is left out of the outcome and
    put in ``failed`` (method -> its one-line reason and exit code: 2 a busy port, 1 a run
    that failed), and the others still run. An exit code when no method finished, or (2)
    when a forced ``--port-offset`` has a busy port: nothing has started then."""
    import numpy as np

    from gcs.mission.distributed import MissionError, run_and_score
    from gcs.mission.launch_spec import LaunchError
    from gcs.mission.preflight import resolve_port_offset

    forced = getattr(args, "port_offset", None)
    if forced is not None:  # every port bound and released before anything starts
        try:
            resolve_port_offset(sc, forced)
        except LaunchError as exc:
            print(f"gcs mission compare: {exc}", file=sys.stderr)
            return EXIT_USAGE
    metrics: dict[str, Any] = {}
    series: dict[str, Any] = {}
    duration = float(sc.run.duration_s if args.duration is None else args.duration)
    for m in METHODS:
        log.info("running %s: vehicle-sim + %d offboard daemons, lockstep ...", m, sc.n)
        try:
            # per method: the ports the previous run freed are probed again
            offset = resolve_port_offset(sc, forced)
            log.info("%s: port offset %d", m, offset)
            doc = run_and_score(sc, out / m, m, args.seed, duration,
                                port_offset=offset, show_progress=True,
                                processes=getattr(args, "processes", None))
        except (LaunchError, MissionError) as exc:
            _note_failed(failed, m, exc,
                         EXIT_USAGE if isinstance(exc, LaunchError) else EXIT_RUN_FAILED)
            continue
        metrics[m] = doc["metrics"]
        with np.load(out / m / "series.npz") as z:
            series[m] = {k: z[k] for k in z.files}
    if not metrics:
        return next(iter(failed.values()))[1] if failed else EXIT_RUN_FAILED
    return metrics, series, _gain_lines(sc)


def _seed_sweep(sc: Scenario, args: argparse.Namespace) -> dict[str, list[dict[str, Any]]]:
    from gcs.mission.procs import worker_pool

    base = sc.seed if args.seed is None else args.seed
    jobs = [(args.scenario, sc.allow_infeasible, sc.allow_unsafe, m, base + s, args.duration)
            for m in METHODS
            for s in range(args.seeds)]
    log.info("seed sweep: %d runs ...", len(jobs))
    with worker_pool(args.jobs) as ex:
        res_all = list(ex.map(_run_one, jobs))
    return {m: [r for (_, _, _, mm, _, _), r in zip(jobs, res_all, strict=True) if mm == m]
            for m in METHODS}


def _layout(args: argparse.Namespace) -> str:
    """How a distributed comparison ran, for the report."""
    n = getattr(args, "processes", None)
    daemons = "one offboard process per agent" if n is None else f"{n} offboard processes"
    return f"distributed (vehicle-sim + {daemons}, lockstep)"


def compare(sc: Scenario, args: argparse.Namespace) -> int:
    """``gcs mission compare`` of a loaded, checked scenario: every method's run, the
    report (of the methods that finished, the failed ones marked with their reason), the
    tables on stdout; the exit code (0; else the first failure's: 1 a run failed, 2 a busy
    port)."""
    from gcs.report.comparison import compare_table, write_report
    from gcs.report.safety_table import safety_table
    from gcs.report.sweep import seeds_table
    from offboard.estimation.bearing import formation_from_scenario
    from swarm_common.scenario.mission_check import plan_for

    out = Path(args.out or "runs/compare")
    failed: dict[str, tuple[str, int]] = {}
    outcome = (_compare_inproc(sc, args, out, failed) if args.inproc
               else _compare_distributed(sc, args, out, failed))
    if isinstance(outcome, int):
        return outcome
    why = {m: line for m, (line, _) in failed.items()}
    metrics, series, gains = outcome
    seeds = _seed_sweep(sc, args) if args.seeds and args.seeds > 1 else None
    form = formation_from_scenario(sc)
    d_safe = sc.controller.d_safe_m
    path = write_report(out, sc.name, metrics, series, form.follower_idx, form.edges, d_safe,
                        gains, seeds,
                        mode="in-process" if args.inproc else _layout(args),
                        tau_safe_s=sc.controller.tau_safe_s,
                        deadline_s=sc.run.formation_deadline_s,
                        mission=plan_for(sc) if sc.mission is not None else None,
                        world=sc.world, failed=why, ids=sc.ids)
    print(compare_table(metrics, d_safe, why))
    print(safety_table(metrics, why))
    if seeds:
        print(seeds_table(seeds, d_safe))
    log.info("wrote %s", path)
    if failed:  # the report has the others; the exit code is the first failure's
        log.error("failed: %s (see %s)", ", ".join(failed), path)
        return next(iter(failed.values()))[1]
    return EXIT_OK


