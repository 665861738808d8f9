"""``offboard --scenario S --agent ID [--mavlink URL] [--zenoh-connect EP ...]``.

One daemon per agent (deployable on each vehicle's companion computer), or with
``--agents 3-8`` several agents packed in one process (:mod:`offboard.daemon.host`: one
Zenoh session and one event loop, each agent its own MAVLink link). Defaults
match the simulator's port scheme (swarm_common/ports.py) and a local Zenoh router
started by ``gcs mission run`` or ``gcs router`` on tcp/127.0.0.1:7447+offset.
"""

from __future__ import annotations

import argparse
import faulthandler
import logging
import os
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

from offboard.daemon import start_gate
from offboard.daemon.limits import (
    LAND_AFTER_S,
    MAX_NAV_GATE_M,
    MIN_LAND_AFTER_S,
    MIN_NAV_GATE_M,
    NAV_GATE_M,
    NAV_GATE_STEPS,
)
from offboard.daemon.mavlink.url import mavlink_url_problem
from offboard.daemon.packing import brief_ids, brief_text, parse_agents
from swarm_common.enums import Method, SensingSource
from swarm_common.inputs import (
    MAX_SCENARIO_BYTES,
    MAX_ZENOH_CONFIG_BYTES,
    BoundedReadError,
    OneLineParser,
    agent_id,
    bounded_file,
    out_file_problem,
    port_offset,
    read_bounded,
    seed,
    zenoh_endpoint,
    zenoh_listen_endpoint,
)
from swarm_common.logsetup import add_log_level_argument, configure_logging
from swarm_common.ports import vehicle_ports
from swarm_common.process_life import die_with_parent, exit_now, freeze_startup
from swarm_common.scenario.files import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    ScenarioError,
    swarm_name_problem,
)
from swarm_common.signing import SigningKeyError, key_file, load_key
from swarm_common.zenoh_session import (
    ZENOH_CONFIG_ENV,
    ZENOH_CONFIG_FLAG,
    default_endpoint,
    open_session,
)

if TYPE_CHECKING:  # the daemon's modules load after the flags and files are checked
    from offboard.daemon.config import DaemonConfig
    from offboard.daemon.core import OffboardDaemon
    from swarm_common.scenario.spec import Scenario

# what :func:`main` imports once the flags are checked: the fork server
# (gcs.launch.preload) imports them before it forks a daemon
RUNTIME_MODULES = (
    "offboard.daemon.core",
    "offboard.daemon.host",
    "offboard.daemon.warmup",
    "offboard.daemon.zenoh.shared_batch",
    "offboard.daemon.zenoh.shared_subs",
    "offboard.estimation.bearing",
    "swarm_common.scenario.model",
)

log = logging.getLogger("offboard.cli")
UNSIGNED_WARNING = ("no --signing-key: the daemon accepts unsigned MAVLink frames from its "
                    "vehicle link, from anyone who reaches its port (gcs keys generate; "
                    "docs/security.md)")


def open_session_saying(
    mode: str, connect: list[str], listen: list[str], config_file: str | None = None
) -> Any:
    """open_session in a helper thread (a client blocks until its router is up), logging
    what it waits for every WAIT_LOG_S; the main thread stays free for signals.
    ``config_file``: Zenoh credentials (default: ``$SWARM_ZENOH_CONFIG`` if set)."""
    from offboard.daemon.core import WAIT_LOG_S
    from offboard.daemon.zenoh.link import ZENOH_ERRORS

    box: dict[str, Any] = {}
    # a bad endpoint (ValueError), zenoh refusing (RuntimeError from open_session, ZError)
    open_errors: tuple[type[Exception], ...] = (ValueError, *ZENOH_ERRORS)

    def opener() -> None:
        try:
            box["session"] = open_session(mode=mode, connect=connect, listen=listen,
                                          config_file=config_file)
        except open_errors as exc:
            box["error"] = exc

    th = threading.Thread(target=opener, name="zenoh-open", daemon=True)
    start = time.monotonic()
    th.start()
    while th.is_alive():
        th.join(WAIT_LOG_S)
        if th.is_alive():
            log.info("waiting for the Zenoh router at %s (%.0f s)",
                     ", ".join(connect) or "no endpoint", time.monotonic() - start)
    if "error" in box:
        raise box["error"]
    return box["session"]


def _zero_or_within(text: object, lo: float, hi: float) -> float | None:
    """``text`` as a number that is 0 or in lo..hi (so finite); None when it is not."""
    try:
        value = float(str(text))
    except ValueError:
        return None
    return value if value == 0.0 or lo <= value <= hi else None


def loss_land_after(text: object) -> float | None:
    """``--loss-land-after``: 0 or a finite number of seconds in MIN_LAND_AFTER_S..3600;
    None when it is not."""
    return _zero_or_within(text, MIN_LAND_AFTER_S, 3600.0)


def nav_gate(text: object) -> float | None:
    """``--nav-gate``: 0 (no check) or a finite number of metres in
    MIN_NAV_GATE_M..MAX_NAV_GATE_M; None when it is not."""
    return _zero_or_within(text, MIN_NAV_GATE_M, MAX_NAV_GATE_M)


def build_parser() -> argparse.ArgumentParser:
    ap = OneLineParser(prog="offboard", description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", required=True, help="scenario TOML file",
                    type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"))
    who = ap.add_mutually_exclusive_group(required=True)
    who.add_argument("--agent", type=agent_id, help="agent id (= MAVLink system id)")
    who.add_argument("--agents", default=None, metavar="IDS",
                     help="several agents in this process: a range 3-8 or a list 1,2,5 "
                     "(one Zenoh session, one event loop, one MAVLink link per agent)")
    ap.add_argument("--mavlink", default=None,
                    help="MAVLink URL (default udpin on the API port; --agent only)")
    ap.add_argument("--port-offset", type=port_offset, default=0,
                    help="shift every port by N")
    ap.add_argument("--swarm", default=None, help="swarm name in Zenoh keys (default: scenario)")
    ap.add_argument("--method", choices=[m.value for m in Method], default=None)
    ap.add_argument("--seed", type=seed, default=None,
                    help="override scenario.seed (0..2^32-1)")
    ap.add_argument("--realtime", action="store_true", help="wall-clock mode (default lockstep)")
    ap.add_argument("--zenoh-connect", nargs="*", type=zenoh_endpoint, default=None,
                    metavar="EP")
    ap.add_argument("--zenoh-listen", nargs="*", type=zenoh_listen_endpoint, default=None,
                    metavar="EP")
    ap.add_argument("--zenoh-mode", choices=("client", "peer"), default="client")
    ap.add_argument(ZENOH_CONFIG_FLAG, default=None, metavar="FILE",
                    type=bounded_file(MAX_ZENOH_CONFIG_BYTES, "zenoh config"),
                    help="Zenoh JSON5 config with this agent's credentials (as written by "
                    f"gcs router --secure-dir; default: ${ZENOH_CONFIG_ENV} if set)")
    ap.add_argument("--manual-start", action="store_true",
                    help="stream setpoints but leave arming and OFFBOARD to the operator (GCS)")
    ap.add_argument("--tlog", default=None,
                    help="write this vehicle's MAVLink .tlog here (--agents: a path with "
                    "{id}, replaced by each agent's id)")
    ap.add_argument("--die-with-parent", action="store_true",
                    help="exit when the parent process (the mission runner) dies (Linux)")
    ap.add_argument("--signing-key", default=None, metavar="PATH", type=key_file,
                    help="MAVLink 2 signing key file (0600): sign everything sent to the "
                         "vehicle, drop unsigned or wrongly signed frames")
    ap.add_argument("--loss-land-after", default=LAND_AFTER_S, metavar="S",
                    help="real time: when the runner or router is lost, land on the "
                    f"coordinated plan S s after the last truth (default {LAND_AFTER_S:g}, at "
                    f"least {MIN_LAND_AFTER_S:g}; 0 = hold until truth is back)")
    ap.add_argument("--nav-gate", default=NAV_GATE_M, metavar="M",
                    help="real time, followers: an estimate more than M m from the vehicle's "
                    f"odometry at {NAV_GATE_STEPS} checks in a row is a navigation fault: hold on "
                    f"odometry, then land (default {NAV_GATE_M:g}; {MIN_NAV_GATE_M:g}.."
                    f"{MAX_NAV_GATE_M:g}; 0 = no check)")
    ap.add_argument("--keep-streams", action="store_true",
                    help="keep the vehicle's default telemetry on the API link (by default the "
                         "daemon switches off the streams it does not read)")
    ap.add_argument("--solo", action="store_true",
                    help="arm and fly without waiting for the rest of the swarm (bench tests "
                    "of one vehicle; default: wait until every agent has published)")
    ap.add_argument("--sensing", choices=[s.value for s in SensingSource],
                    default=SensingSource.TRUTH.value,
                    help="sensor inputs: the simulator's truth (default) or every vehicle's "
                    "own odometry published by its daemon (no simulator truth needed)")
    ap.add_argument(ALLOW_INFEASIBLE_FLAG, action="store_true",
                    help="run a scenario that fails the feasibility check, with a warning")
    ap.add_argument(ALLOW_UNSAFE_FLAG, action="store_true",
                    help="run a scenario that breaks a load-time safety assumption, with a "
                    "warning")
    add_log_level_argument(ap)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.mavlink is not None and (why := mavlink_url_problem(args.mavlink)) is not None:
        print(f"offboard: --mavlink {args.mavlink!r}: {why}", file=sys.stderr)
        return 2
    configure_logging(args.log_level)
    # SIGUSR1 writes every thread's stack to stderr (the daemon's log): a stalled or hung
    # daemon on a companion computer can be inspected without stopping it
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    if args.die_with_parent and (
            why := die_with_parent(signal.SIGTERM, os.getppid())()) is not None:
        print(f"offboard: --die-with-parent: {why}", file=sys.stderr)
        return 2
    key = None
    if args.signing_key is not None:
        try:
            key = load_key(args.signing_key)
        except SigningKeyError as exc:
            print(f"offboard: --signing-key: {exc}", file=sys.stderr)
            return 2
    if (why := file_problem(args)) is not None:
        print(f"offboard: {why}", file=sys.stderr)
        return 2
    from swarm_common.scenario.model import load_scenario

    try:
        sc = load_scenario(args.scenario, args.allow_infeasible, args.allow_unsafe)
    except ScenarioError as exc:
        print(f"offboard: {exc}", file=sys.stderr)
        return 2
    if (why := sc.process_problem()) is not None:
        print(f"offboard: {sc.path}: {why}", file=sys.stderr)
        return 2
    ids = agent_ids(args, sc.ids)
    if isinstance(ids, str):
        print(f"offboard: {ids}", file=sys.stderr)
        return 2
    if args.swarm is not None and (problem := swarm_name_problem(args.swarm)) is not None:
        print(f"offboard: --swarm {args.swarm!r}: {problem}", file=sys.stderr)
        return 2
    if args.tlog is not None:
        for i in ids:
            tlog = args.tlog.replace("{id}", str(i))
            if (why := out_file_problem(tlog, "--tlog")) is not None:
                print(f"offboard: {why}", file=sys.stderr)
                return 2
    land_after = loss_land_after(args.loss_land_after)
    if land_after is None:
        print(f"offboard: --loss-land-after {args.loss_land_after!r}: must be 0 or a number "
              f"of seconds in {MIN_LAND_AFTER_S:g}..3600", file=sys.stderr)
        return 2
    gate = nav_gate(args.nav_gate)
    if gate is None:
        print(f"offboard: --nav-gate {args.nav_gate!r}: must be 0 or a number of metres in "
              f"{MIN_NAV_GATE_M:g}..{MAX_NAV_GATE_M:g}", file=sys.stderr)
        return 2
    if key is None:  # every check passed: the one line before the daemon starts
        log.warning("%s", UNSIGNED_WARNING)
    connect = args.zenoh_connect
    if connect is None:
        connect = [default_endpoint(args.port_offset)]
    cfgs = [daemon_config(args, sc, i, connect, key, land_after, gate) for i in ids]
    from offboard.daemon.zenoh.link import ZENOH_ERRORS

    # a bad endpoint (ValueError), zenoh refusing (RuntimeError from open_session, ZError)
    open_errors: tuple[type[Exception], ...] = (ValueError, *ZENOH_ERRORS)
    try:
        session = open_session_saying(cfgs[0].zenoh_mode, connect, cfgs[0].zenoh_listen,
                                      args.zenoh_config)
    except open_errors as exc:
        print(f"offboard: cannot open Zenoh session ({connect}): {exc}", file=sys.stderr)
        return 2
    try:
        return run_daemons(cfgs, session, "-".join(str(i) for i in ids))
    finally:
        session.close()


def file_problem(args: argparse.Namespace) -> str | None:
    """``$SWARM_ZENOH_CONFIG``, when no ``--zenoh-config`` is given: a regular file within
    its cap, read before anything starts (:mod:`swarm_common.inputs`; the flag itself was
    checked as it was parsed); None, or the one-line error."""
    path = os.environ.get(ZENOH_CONFIG_ENV) or None
    if args.zenoh_config is not None or path is None:
        return None
    try:
        read_bounded(path, MAX_ZENOH_CONFIG_BYTES, "zenoh config")
    except BoundedReadError as exc:
        return f"${ZENOH_CONFIG_ENV}: {exc}"
    return None


def agent_ids(args: argparse.Namespace, ids: list[int]) -> list[int] | str:
    """The agents this process runs (``--agent`` or ``--agents``), or a one-line error."""
    if args.agent is not None:
        if args.agent not in ids:
            return f"--agent {args.agent}: not an agent of the scenario {brief_ids(ids)}"
        return [args.agent]
    try:
        chosen = parse_agents(args.agents)
    except ValueError as exc:
        return f"--agents {brief_text(args.agents)}: {exc}"
    if bad := [i for i in chosen if i not in ids]:  # lists cut: --agents 1-300 is 292 ids
        return (f"--agents {brief_text(args.agents)}: {brief_ids(bad)} not agents of the "
                f"scenario {brief_ids(ids)}")
    if args.mavlink is not None:
        return "--mavlink names one vehicle: use it with --agent (--agents: default ports)"
    if args.tlog is not None and "{id}" not in args.tlog:
        return f"--tlog {args.tlog!r}: with --agents the path needs {{id}}"
    return chosen


def daemon_config(args: argparse.Namespace, sc: Scenario, agent_id: int, connect: list[str],
                  key: bytes | None, land_after: float, gate: float) -> DaemonConfig:
    """One agent's :class:`DaemonConfig` from the checked command line."""
    from offboard.daemon.config import DaemonConfig
    from offboard.daemon.mavlink.link import COMP_ONBOARD

    ports = vehicle_ports(agent_id, args.port_offset)
    url = args.mavlink or f"udpin:127.0.0.1:{ports.api_remote}"
    method = Method(args.method) if args.method else sc.controller.method
    cfg = DaemonConfig(
        scenario=sc,
        agent_id=agent_id,
        mavlink_url=url,
        swarm=args.swarm or sc.name,
        method=method,
        seed=args.seed,
        lockstep=not args.realtime,
        tlog=None if args.tlog is None else args.tlog.replace("{id}", str(agent_id)),
        zenoh_connect=connect,
        zenoh_listen=args.zenoh_listen or [],
        zenoh_mode=args.zenoh_mode,
        manual_start=args.manual_start,
        signing_key=key,
        loss_land_after=land_after,
        solo=args.solo,
        keep_streams=args.keep_streams,
        sensing=SensingSource(args.sensing),
        nav_gate_m=gate,
    )
    log.info("agent %d: vehicle link %s (system %d, component %d, signing %s); Zenoh %s "
             "%s, swarm %r; sensing %s; %s", cfg.agent_id, url, cfg.agent_id, COMP_ONBOARD,
             "on" if key is not None else "off", cfg.zenoh_mode,
             " ".join([*(f"connect {ep}" for ep in connect),
                       *(f"listen {ep}" for ep in cfg.zenoh_listen)]) or "no endpoint",
             cfg.swarm, cfg.sensing, "--solo" if cfg.solo else "arms once its swarm is ready")
    return cfg


def run_daemons(cfgs: list[DaemonConfig], session: Any, name: str) -> int:
    """Build the daemons on ``session`` and run them: alone (``--agent``) or packed
    (:class:`offboard.daemon.host.DaemonHost`). ``$OFFBOARD_PROFILE``: a developer aid,
    cProfile (the main thread's CPU time, not Zenoh's threads) of the whole run written
    to ``$OFFBOARD_PROFILE.<name>``."""
    from offboard.daemon.core import OffboardDaemon
    from offboard.daemon.host import DaemonHost
    from offboard.daemon.warmup import warm_kernels
    from offboard.daemon.zenoh.link import FIFO_DEPTH
    from offboard.daemon.zenoh.shared_batch import SharedBatch
    from offboard.daemon.zenoh.shared_subs import SharedSubscriptions
    from offboard.estimation.bearing import formation_from_scenario
    from swarm_common.blas import single_thread_blas

    single_thread_blas()  # tiny matrices: BLAS worker threads only cost (swarm_common.blas)
    form = formation_from_scenario(cfgs[0].scenario)
    warm_kernels(cfgs[0].scenario, cfgs[0].method, form)  # before any daemon's first step
    daemons: list[OffboardDaemon] = []
    # packed: one Zenoh subscriber per key for all the process's daemons (shared_subs), and
    # their received estimates as one batch per step (shared_batch)
    packed = len(cfgs) > 1
    shared = SharedSubscriptions(session, FIFO_DEPTH) if packed else None
    batch = SharedBatch({aid: j for j, aid in enumerate(form.ids)}) if packed else None
    for cfg in cfgs:
        try:
            daemons.append(OffboardDaemon(cfg, session, form, shared, batch))
        except (OSError, ValueError) as exc:
            print(f"offboard: cannot open MAVLink {cfg.mavlink_url}: {exc}", file=sys.stderr)
            for d in daemons:
                d.close()
            return 2
    run = daemons[0].run if len(daemons) == 1 else DaemonHost(daemons).run
    start_gate.release()  # the CPU-heavy start-up is over (offboard.daemon.start_gate)
    freeze_startup()  # later collections skip the start-up's objects (process_life)
    prof_path = os.environ.get("OFFBOARD_PROFILE")
    if not prof_path:
        return run()
    import cProfile

    prof = cProfile.Profile(time.thread_time)
    try:
        return int(prof.runcall(run))
    finally:
        prof.dump_stats(f"{prof_path}.{name}")


if __name__ == "__main__":
    exit_now(main())
