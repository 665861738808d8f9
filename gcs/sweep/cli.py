"""``gcs mission sweep``: many in-process runs in parallel, one metrics row per run.

    gcs mission sweep SCENARIO... --seeds 1-100 --methods rcbf,apf,none --jobs N --out DIR
                      [--duration S] [--cluster tcp://HOST:8786] [--resume]

Every (scenario, method, seed) is one :func:`gcs.sweep.jobs.run_job` of the scenario's text
(read once here) in a local worker process (:mod:`gcs.sweep.local`), or with ``--cluster`` a
task on a Dask scheduler (:mod:`gcs.sweep.cluster`, imported only then); progress on stderr
(runs done, failed, time left). Each row is appended to ``DIR/runs.csv``
(:data:`gcs.report.sweep.CSV_COLUMNS`) as it finishes (:class:`gcs.sweep.rows.RowSink`); at
the end runs.csv is rewritten in (scenario, method, seed) order with ``DIR/summary.md`` and
``DIR/summary.png`` (:mod:`gcs.report.sweep`). ``--resume`` keeps the ``ok`` rows already in
``DIR/runs.csv`` and runs only the rest. Bad input (scenario, seeds, methods, jobs,
duration, cluster): one line on stderr, exit 2.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gcs.exit_codes import EXIT_USAGE
from swarm_common.enums import Method
from swarm_common.inputs import MAX_SCENARIO_BYTES, bounded_file, out_dir_problem
from swarm_common.scenario.files import ALLOW_INFEASIBLE_FLAG, ALLOW_UNSAFE_FLAG

if TYPE_CHECKING:
    from swarm_common.scenario.spec import Scenario

log = logging.getLogger(__name__)

def cmd_mission_sweep(args: argparse.Namespace) -> int:
    """``gcs mission sweep``: exit 0 (even with crashed runs: they are in runs.csv), 2 on
    bad input."""
    # the sweep's machinery (runs, report, figures) loads once the flags are parsed: a bad
    # flag or file is refused without it
    from gcs.sweep.jobs import (
        SweepInputError,
        load_all,
        parse_address,
        parse_duration,
        parse_jobs,
        parse_methods,
        parse_seeds,
    )

    try:
        seeds = parse_seeds(args.seeds)
        methods = parse_methods(args.methods)
        workers = parse_jobs(args.jobs)
        duration = parse_duration(args.duration)
        if args.cluster is not None:
            parse_address(args.cluster)
        scenarios = load_all(args.scenario, args.allow_infeasible, args.allow_unsafe)
    except SweepInputError as exc:
        print(f"gcs mission sweep: {exc}", file=sys.stderr)
        return EXIT_USAGE
    client = None
    if args.cluster is not None:  # the engine is imported only here
        from gcs.sweep.cluster import connect

        try:
            client = connect(args.cluster)
        except SweepInputError as exc:
            print(f"gcs mission sweep: {exc}", file=sys.stderr)
            return EXIT_USAGE
    try:
        return _sweep_into(args, client, scenarios, methods, seeds, duration, workers)
    finally:
        if client is not None:
            client.close()


def _sweep_into(
    args: argparse.Namespace, client: Any, scenarios: list[tuple[str, str, Scenario]],
    methods: list[str], seeds: list[int], duration: float | None, workers: int,
) -> int:
    from gcs.report.sweep import write_outputs
    from gcs.sweep.jobs import make_jobs
    from gcs.sweep.local import run_sweep
    from gcs.sweep.rows import RowSink, resumable_rows

    out = Path(args.out or f"runs/sweep-{time.strftime('%Y%m%d-%H%M%S')}")
    if (why := out_dir_problem(out, "--out")) is not None:  # before any run starts
        print(f"gcs mission sweep: {why}", file=sys.stderr)
        return EXIT_USAGE
    out.mkdir(parents=True, exist_ok=True)
    every = make_jobs(scenarios, methods, seeds, duration)
    try:
        kept = (resumable_rows(out / "runs.csv", {j.key: j.duration_s for j in every})
                if args.resume else [])
    except ValueError as exc:
        print(f"gcs mission sweep: {exc}", file=sys.stderr)
        return EXIT_USAGE
    sink = RowSink(out / "runs.csv", kept)
    jobs = [j for j in every if j.key not in sink.keys]
    where = f"cluster {args.cluster}" if client is not None else f"{workers} workers"
    log.info("sweep: %d runs on %s -> %s (%d kept)", len(jobs), where, out, len(kept))
    t0 = time.monotonic()
    specs = {sc.name: sc for _, _, sc in scenarios}
    try:
        if client is None:
            run_sweep(jobs, workers, on_row=sink.add)
        else:
            from gcs.sweep.cluster import run_cluster_sweep

            run_cluster_sweep(client, jobs, on_row=sink.add)
    except (KeyboardInterrupt, SystemExit):
        sink.close()
        if sink.rows:  # an interrupted sweep keeps the runs that finished
            write_outputs(out, sink.rows, specs, methods, wall_s=time.monotonic() - t0)
            log.warning("interrupted: %d of %d runs written to %s", len(sink.rows),
                        len(jobs) + len(kept), out)
        raise
    finally:
        sink.close()
    write_outputs(out, sink.rows, specs, methods, wall_s=time.monotonic() - t0)
    n_bad = sum(r["status"] != "ok" for r in sink.rows)
    if n_bad:
        log.warning("%d of %d runs crashed (status 'crashed' in runs.csv)", n_bad, len(sink.rows))
    log.info("wrote %s/runs.csv, summary.md, summary.png", out)
    return 0


def add_sweep_parser(msub: argparse._SubParsersAction) -> None:
    """Register ``gcs mission sweep`` (values validated by the command: one-line errors)."""
    s = msub.add_parser("sweep", help="many seeds x methods x scenarios in parallel")
    s.add_argument("scenario", nargs="+", help="scenario file(s)",
                   type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"))
    s.add_argument("--seeds", default="1-20", help="range 1-100 or list 1,4,9 (default 1-20)")
    s.add_argument("--methods", default=",".join(str(m) for m in Method),
                   help="comma-separated methods (default: all)")
    s.add_argument("--jobs", default=None, help="worker processes (default: CPU count)")
    s.add_argument("--duration", default=None, help="seconds per run (default: scenario)")
    s.add_argument("--out", default=None, help="output directory (default runs/sweep-TIME)")
    s.add_argument("--cluster", default=None, metavar="tcp://HOST:PORT",
                   help="run on this Dask scheduler instead of local processes (docs/sweeps.md)")
    s.add_argument("--resume", action="store_true",
                   help="keep the ok runs already in OUT/runs.csv and run only the rest")
    s.add_argument(ALLOW_INFEASIBLE_FLAG, action="store_true",
                   help="run scenarios that fail the feasibility check, with a warning")
    s.add_argument(ALLOW_UNSAFE_FLAG, action="store_true",
                   help="run scenarios that break a load-time safety assumption, with a warning")
    s.set_defaults(func=cmd_mission_sweep)
