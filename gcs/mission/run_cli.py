"""``gcs mission run SCENARIO`` without ``--inproc``: one distributed run from the command
line, its exit status and what it prints (the table of exit codes: :mod:`gcs.cli`)."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Any

from gcs.exit_codes import EXIT_RUN_FAILED, EXIT_USAGE
from gcs.formation.vehicle import FORMATION_PORT
from gcs.mission.distributed import MissionError, run_and_score
from gcs.mission.launch_spec import LaunchError, SigningChoice, split_packs
from gcs.mission.preflight import resolve_port_offset
from gcs.mission.run_output import out_dir_problem, print_result
from gcs.mission.score import default_out_dir, late_steps, lockstep_misses
from gcs.records.live import start_live
from gcs.records.live_flags import live_endpoint
from gcs.report.verdict import safety_exit_status
from swarm_common.enums import DefaultStreams
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)


def cli_run(args: Any, sc: Scenario) -> int:
    """``gcs mission run SCENARIO`` (distributed), at ``--port-offset`` or, without it, the
    first offset whose ports are all free (:func:`~gcs.mission.preflight.resolve_port_offset`).
    Exit 2: bad input or a busy port;
    1: a child died or the run stalled; 3: the safety verdict (:mod:`gcs.exit_codes`)."""
    method = str(args.method or sc.controller.method)
    duration = float(sc.run.duration_s if args.duration is None else args.duration)
    if args.kill_agent is not None and args.kill_agent not in sc.ids:
        print(f"gcs mission run: --kill-agent {args.kill_agent}: not an agent of {sc.path} "
              f"{sc.ids}", file=sys.stderr)
        return EXIT_USAGE
    if args.kill_at is not None and args.kill_agent is None:
        print("gcs mission run: --kill-at needs --kill-agent", file=sys.stderr)
        return EXIT_USAGE
    formation = getattr(args, "formation_vehicle", False)
    if (why := sc.process_problem()) is not None:  # e.g. agent ids past MAVLink's 255
        print(f"gcs mission run: {sc.path}: {why}", file=sys.stderr)
        return EXIT_USAGE
    try:
        live_endpoint(args)  # before the port choice logs anything: the refusal is one line
        out = Path(args.out) if args.out else default_out_dir(sc, method)
        signing = SigningChoice.from_args(args)
        split_packs(list(sc.ids), getattr(args, "processes", None))  # a bad --processes
        # every port bound and released before anything starts: a forced offset with a busy
        # port stops here (exit 2, one line); without one, the first offset all free
        offset = resolve_port_offset(sc, args.port_offset,
                                     FORMATION_PORT if formation else None)
    except (ValueError, LaunchError) as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if (why := out_dir_problem(out)) is not None:  # the default run directory too
        print(f"gcs mission run: {why}", file=sys.stderr)
        return EXIT_USAGE
    try:  # --foxglove: its port bound before anything starts (busy: exit 2)
        live = start_live(args, sc, method, args.seed)
    except (ValueError, OSError) as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        doc = run_and_score(
            sc, out, method, args.seed, duration, realtime=args.realtime,
            port_offset=offset, kill_agent=args.kill_agent, kill_at=args.kill_at,
            show_progress=True, land_at=getattr(args, "land_at", None), signing=signing,
            processes=getattr(args, "processes", None),
            default_streams=DefaultStreams(getattr(args, "default_streams", "always")),
            formation_port=FORMATION_PORT + offset if formation else None, live=live,
        )
        if live is not None:
            live.finish(doc)
    except LaunchError as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except MissionError as exc:
        if live is not None:
            live.fail(str(exc))
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_RUN_FAILED
    finally:
        if live is not None:
            live.close()
    log.info("wrote %s/metrics.json, series.npz, record.mcap, vehicle_*.tlog, *.log", out)
    if doc["run"]["failed_agents"]:
        log.warning("failed agents: %s", doc["run"]["failed_agents"])
    if not args.realtime:
        warn_misses(doc)
    print_result(doc, args.json)
    return safety_exit_status(doc["metrics"], method)


def warn_misses(doc: dict[str, Any]) -> None:
    """Say, when it happened, that a lockstep run took steps without every answer or
    estimate, so it may differ from the in-process run, and name the cause when known."""
    run = doc["run"]
    misses = lockstep_misses(run)
    if not misses:
        return
    stopped = [p.get("name", "?") for p in run.get("stopped_processes", [])]
    failed = [f"agent {a}'s daemon" for a in run["failed_agents"]]
    if stopped or failed:  # the fault is known: name it, not the machine
        why = "; ".join(filter(None, [
            f"stopped: {', '.join(stopped)}" if stopped else "",
            f"dead: {', '.join(failed)}" if failed else ""]))
    elif late_steps(doc):
        why = ("lockstep timeouts: a daemon too slow for this machine; fewer daemon "
               "processes (--processes N) avoid it")
    else:
        why = "a daemon too slow for this machine; fewer daemon processes avoid it"
    log.warning("lockstep gave up waiting (%s; %s), so this run may differ from the "
                "in-process run", "; ".join(misses[:4]), why)
