"""``gcs`` command line: ``gcs mission run|compare|sweep SCENARIO``, ``gcs router``,
``gcs dashboard``, ``gcs keys generate --out PATH`` (a MAVLink signing key, :mod:`gcs.keys`),
``gcs scenario grid|ring|sphere|helix ...`` (a generated formation, :mod:`gcs.scenario_gen`).

``mission run`` and ``mission compare`` are distributed (real processes, lockstep) unless
``--inproc``; the seed sweep of ``compare --seeds N`` and ``mission sweep``
(:mod:`gcs.sweep`) always run in process.
``gcs --log-level {debug,info,warning,error} ...`` sets the diagnostics level.
``mission run --fault-drop P --fault-delay-ms MS ... --fault-link mavlink|zenoh|both``
injects transport faults in a distributed run (docs/faults.md).

Exit codes (every command): :mod:`gcs.exit_codes` (3: a safety filter's run whose safety
verdict is not "safe").

Subcommands are registered in :data:`COMMANDS` as ``name -> add_parser(subparsers)``;
each ``add_parser`` sets ``func`` on its parser (``func(args) -> int``).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType

from gcs.exit_codes import (
    EXIT_INTERRUPTED,
    EXIT_RUN_FAILED,
    EXIT_TERMINATED,
    EXIT_USAGE,
)
from gcs.mission.agents import AUTO_WORKERS, MAX_WORKERS
from gcs.mission.fault_flags import add_fault_flags, write_fault_scenario
from gcs.mission.launch_spec import add_signing_flags
from gcs.records.cli import add_log_parser
from gcs.records.live_flags import add_live_flags, live_endpoint
from swarm_common.enums import DefaultStreams, Method
from swarm_common.inputs import (
    MAX_SCENARIO_BYTES,
    OneLineParser,
    bounded_file,
    float_in,
    int_in,
    port_offset,
    seed,
    zenoh_listen_endpoint,
)
from swarm_common.logsetup import add_log_level_argument, configure_logging
from swarm_common.process_life import exit_now
from swarm_common.scenario.model import ALLOW_INFEASIBLE_FLAG, ALLOW_UNSAFE_FLAG, Scenario
from swarm_common.zenoh_session import default_endpoint

log = logging.getLogger(__name__)

METHODS = [str(m) for m in Method]


def _load(path: str, allow_infeasible: bool, allow_unsafe: bool) -> Scenario:
    """Load ``path`` or exit 2 with one line (``--allow-infeasible``, ``--allow-unsafe``)."""
    from swarm_common.scenario.model import ScenarioError, load_scenario

    try:
        return load_scenario(path, allow_infeasible, allow_unsafe)
    except ScenarioError as exc:
        print(f"gcs: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None


def cmd_mission_run(args: argparse.Namespace) -> int:
    try:  # the live view's flags first: a refusal before any preflight WARNING is one line
        live_endpoint(args)
    except ValueError as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    sc = _load(args.scenario, args.allow_infeasible, args.allow_unsafe)
    _check_run_args(args, sc, "mission run")
    try:
        faulted = write_fault_scenario(args, sc)
    except ValueError as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if faulted is not None:
        sc = _load(str(faulted), sc.allow_infeasible, sc.allow_unsafe)
    if not args.inproc:
        from gcs.mission.run_cli import cli_run

        return cli_run(args, sc)
    from gcs.mission.agents.shards import ShardError, workers_for
    from gcs.mission.inproc import run_inproc
    from gcs.mission.launch_spec import LaunchError
    from gcs.mission.preflight import check_physics
    from gcs.mission.run_output import print_result, write_run
    from gcs.records.live import start_live
    from gcs.report.verdict import safety_exit_status

    try:  # the observer's gains on this graph, the deadline against --duration
        check_physics(sc, float(sc.run.duration_s if args.duration is None else args.duration))
        live = start_live(args, sc, str(args.method or sc.controller.method), args.seed)
    except (LaunchError, ValueError, OSError) as exc:
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        res = run_inproc(sc, args.method, seed=args.seed, duration=args.duration,
                         progress=True, land_at=args.land_at, live=live,
                         workers=workers_for(args.workers, sc.n))
        if live is not None:
            live.finish(res.document())
    except ShardError as exc:  # a failed worker's traceback is in the log already
        if live is not None:
            live.fail(str(exc))
        print(f"gcs mission run: {exc}", file=sys.stderr)
        return EXIT_RUN_FAILED
    finally:
        if live is not None:
            live.close()
    if args.out:  # checked writable before the run; a fallback folder if it fails now
        where = write_run(Path(args.out), res.document(), res.series, sc)
        log.info("wrote %s/metrics.json, series.npz, record.mcap", where)
    print_result(res.document(), args.json)
    return safety_exit_status(res.metrics, res.method)


def _secure_dir_problem(d: Path) -> str | None:
    """Why the router cannot use ``--secure-dir d``, or None: credentials already there are
    used as they are; otherwise they are written there, so it must be a folder that can be
    created and written (a NUL byte, ``/proc/...``: one line before the router starts)."""
    from swarm_common.inputs import out_dir_problem

    if (d / "router.json5").is_file():  # False for a path with a NUL byte
        return None
    return out_dir_problem(d, "--secure-dir")


def cmd_router(args: argparse.Namespace) -> int:
    sc = (None if args.scenario is None
          else _load(args.scenario, args.allow_infeasible, args.allow_unsafe))
    if (sc is None) != (args.secure_dir is None):
        print("gcs router: --scenario and --secure-dir go together", file=sys.stderr)
        return EXIT_USAGE
    if args.secure_dir is not None and (why := _secure_dir_problem(args.secure_dir)):
        print(f"gcs router: {why}", file=sys.stderr)
        return EXIT_USAGE
    from gcs.mission.router import run_router

    return run_router(args.listen, sc, args.secure_dir, args.swarm)


def add_keys(sub: argparse._SubParsersAction) -> None:
    from gcs.keys import add_keys_parser

    add_keys_parser(sub)


def add_router_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("router", help="run a Zenoh router (multi-machine setups)")
    p.add_argument("--listen", nargs="+", type=zenoh_listen_endpoint,
                   default=[default_endpoint()], metavar="EP",
                   help=f"endpoints to listen on (default {default_endpoint()})")
    p.add_argument("--scenario", default=None,
                   type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"),
                   help="authenticate and apply this swarm's ACL (docs/security.md)")
    p.add_argument("--secure-dir", type=Path, default=None, metavar="DIR",
                   help="credentials + ACL: generated here (0700/0600) unless present")
    p.add_argument("--swarm", default=None, help="swarm name (default: the scenario name)")
    _add_allow_infeasible(p)
    p.set_defaults(func=cmd_router)


def add_scenario(sub: argparse._SubParsersAction) -> None:
    from gcs.scenario_gen import add_scenario_parser

    add_scenario_parser(sub)


def add_dashboard(sub: argparse._SubParsersAction) -> None:
    from gcs.dashboard.cli import add_dashboard_parser

    add_dashboard_parser(sub)


def cmd_mission_compare(args: argparse.Namespace) -> int:
    sc = _load(args.scenario, args.allow_infeasible, args.allow_unsafe)
    _check_run_args(args, sc, "mission compare")
    from gcs.mission.compare_cli import compare

    return compare(sc, args)


MAX_DURATION_S = 3600.0  # as scenario.duration_s: the recorder preallocates the run
MAX_MISSION_TIME_S = 1e6  # --land-at, --kill-at: any time after the run is simply never reached

_duration = float_in(0.0, MAX_DURATION_S, lo_open=True, unit="s")
_non_negative_seconds = float_in(0.0, MAX_MISSION_TIME_S, unit="s")
# the shared flag types (swarm_common.inputs): the same bounds as vehicle-sim and offboard
_int_in = int_in


def _workers(text: str) -> int | str:
    """``--workers``: ``auto`` or a count of processes, 1..MAX_WORKERS."""
    if text == AUTO_WORKERS:
        return AUTO_WORKERS
    return _int_in(1, MAX_WORKERS, "a count of processes (or auto)")(text)


_port_offset = port_offset
_seed = seed


def _check_run_args(args: argparse.Namespace, sc: Scenario, cmd: str) -> None:
    """Flags that need the scenario or the file system: exit 2 with one line."""
    from gcs.mission.run_output import out_dir_problem

    problem = None
    if args.duration is not None and args.duration < sc.control_dt:
        problem = (f"--duration {args.duration:g}: shorter than one control step "
                   f"({sc.control_dt:g} s)")
    elif args.out and out_dir_problem(Path(args.out)):
        problem = out_dir_problem(Path(args.out))
    elif not args.inproc and args.workers != AUTO_WORKERS:
        problem = ("--workers is for --inproc (a distributed run packs its daemons with "
                   "--processes)")
    if problem:
        print(f"gcs {cmd}: {problem}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def _add_allow_infeasible(p: argparse.ArgumentParser) -> None:
    p.add_argument(ALLOW_INFEASIBLE_FLAG, action="store_true",
                   help="run a scenario that fails the feasibility check (docs/scenarios.md), "
                   "with a warning")
    p.add_argument(ALLOW_UNSAFE_FLAG, action="store_true",
                   help="run a scenario that breaks a load-time safety assumption "
                   "(docs/safety.md), with a warning per assumption")


def add_mission_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("mission", help="run or compare missions")
    msub = p.add_subparsers(dest="mission_cmd", required=True)
    r = msub.add_parser("run", help="run one mission")
    r.add_argument("scenario", type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"))
    r.add_argument("--inproc", action="store_true", help="all in one process (no MAVLink)")
    r.add_argument("--method", choices=METHODS, default=None)
    r.add_argument("--seed", type=_seed, default=None)
    r.add_argument("--duration", type=_duration, default=None,
                   help="seconds (default: scenario)")
    r.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    r.add_argument("--out", default=None, help="directory for metrics.json + series.npz")
    r.add_argument("--land-at", type=_non_negative_seconds, default=None, metavar="T",
                   help="coordinated land-all at mission time T s (docs/lifecycle.md)")
    r.add_argument("--workers", type=_workers, default=AUTO_WORKERS, metavar="N|auto",
                   help="with --inproc: step the agents in N processes, this one included "
                   "(the same run bit for bit); auto (default): 1 below 64 agents, else "
                   "one per CPU (docs/performance.md)")
    d = r.add_argument_group("distributed runs (without --inproc)")
    d.add_argument("--realtime", action="store_true", help="wall-clock ticks, not lockstep")
    d.add_argument("--port-offset", type=_port_offset, default=None,
                   help="added to every UDP/TCP port (default: the first of 0, 1000, ... "
                   "whose ports are all free; with N, a busy port is exit 2)")
    d.add_argument("--kill-agent", type=int_in(1, 255, "an agent id"), default=None,
                   help="kill this agent's process ...")
    d.add_argument("--kill-at", type=_non_negative_seconds, default=None,
                   help="... at this mission time (s)")
    d.add_argument("--processes", type=_int_in(1, 10_000), default=None, metavar="N",
                   help="pack the agents' daemons into N processes (default: one per agent; "
                   "each packed process authenticates as one Zenoh user)")
    d.add_argument("--default-streams", choices=[x.value for x in DefaultStreams],
                   default=DefaultStreams.ALWAYS.value,
                   help="the simulator's default telemetry: always (as PX4: to the GCS port "
                   "whether or not anyone listens) or on-contact (HEARTBEAT only until a "
                   "ground station there speaks; cheaper for large batch runs)")
    d.add_argument("--formation-vehicle", action="store_true",
                   help="serve the formation as one MAVLink vehicle (system id 200) on UDP "
                   "14560 + offset for QGroundControl, MAVProxy or MAVSDK (needs a scenario "
                   "with a [mission]; docs/missions.md)")
    add_signing_flags(d)
    add_fault_flags(d)
    add_live_flags(r)
    _add_allow_infeasible(r)
    r.set_defaults(func=cmd_mission_run)
    c = msub.add_parser("compare", help="run every method and write a report")
    c.add_argument("scenario", type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"))
    c.add_argument("--inproc", action="store_true")
    c.add_argument("--seed", type=_seed, default=None)
    c.add_argument("--duration", type=_duration, default=None)
    c.add_argument("--seeds", type=_int_in(0, 100_000), default=0,
                   help="also sweep N seeds per method")
    c.add_argument("--jobs", type=_int_in(1, 256), default=2,
                   help="parallel processes for the sweep")
    c.add_argument("--workers", type=_workers, default=AUTO_WORKERS, metavar="N|auto",
                   help="with --inproc: each run's agents in N processes, as for "
                   "'mission run' (default auto)")
    c.add_argument("--out", default=None, help="report directory (default runs/compare)")
    c.add_argument("--port-offset", type=_port_offset, default=None,
                   help="distributed: shift every port by N (default: the first of 0, 1000, "
                   "... whose ports are all free, per method; with N, a busy port is exit 2)")
    c.add_argument("--processes", type=_int_in(1, 10_000), default=None, metavar="N",
                   help="distributed: pack the daemons into N processes (default: one per "
                   "agent)")
    _add_allow_infeasible(c)
    c.set_defaults(func=cmd_mission_compare)
    from gcs.sweep.cli import add_sweep_parser

    add_sweep_parser(msub)


COMMANDS: dict[str, Callable[[argparse._SubParsersAction], None]] = {
    "mission": add_mission_parser,
    "router": add_router_parser,
    "dashboard": add_dashboard,
    "keys": add_keys,
    "scenario": add_scenario,
    "log": add_log_parser,
}


def build_parser() -> argparse.ArgumentParser:
    ap = OneLineParser(prog="gcs", description="bearing-swarm ground station")
    add_log_level_argument(ap)
    sub = ap.add_subparsers(dest="command", required=True)
    for add in COMMANDS.values():
        add(sub)
    return ap


def _terminated(signum: int, frame: FrameType | None) -> None:
    """SIGTERM during a mission: unwind (the runners' ``finally`` stop every child)."""
    raise SystemExit(EXIT_TERMINATED)


def interrupt_cause(exc: BaseException) -> BaseException | None:
    """The KeyboardInterrupt or SystemExit inside ``exc``'s cause chain, if any.

    A signal handler that raises (Ctrl-C; SIGTERM → exit 143, :func:`_terminated`) runs at
    the next Python instruction. When that instruction is a callback of compiled code
    (numba boxing a kernel's result, swarm_common.jit), numba reports the handler's
    exception as the cause of a ``SystemError``; :func:`main` unwraps it so the run exits
    as the signal asked, without a traceback.
    """
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt | SystemExit):
            return cur
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return None


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``gcs``; returns the exit code (table in the module docstring)."""
    args = build_parser().parse_args(argv)
    configure_logging(args.log_level)
    if args.command == "mission":
        signal.signal(signal.SIGTERM, _terminated)
        # Ctrl-C must stop a run even when the shell that started us ignored SIGINT (a
        # background job of a non-interactive shell inherits SIG_IGN)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        try:
            return int(args.func(args) or 0)
        except SystemError as exc:  # a signal's exception wrapped by compiled code
            cause = interrupt_cause(exc)
            if cause is None:
                raise
            raise cause from None
    except KeyboardInterrupt:
        print(f"gcs {args.command}: interrupted; every process stopped", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    exit_now(main())  # no interpreter teardown (swarm_common.process_life)
