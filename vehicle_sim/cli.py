"""``vehicle-sim``: SITL-style multi-vehicle MAVLink simulator (docs/conventions.md).

Exit codes: 0 on SIGINT/SIGTERM or when ``--duration`` is reached; 2 on a bad scenario,
a bad option or a busy port (one line on stderr naming it). Diagnostics go through
``logging`` (``--log-level``; ``--quiet`` = at most warnings); the last line on stderr is
the ``stats:`` summary.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import time
from types import FrameType
from typing import TYPE_CHECKING

from swarm_common.blas import single_thread_blas
from swarm_common.enums import DefaultStreams, FailsafeAction
from swarm_common.inputs import (
    MAX_PARAMS_BYTES,
    MAX_SCENARIO_BYTES,
    MAX_ZENOH_CONFIG_BYTES,
    BoundedReadError,
    OneLineParser,
    bounded_file,
    finite_float,
    float_in,
    host,
    int_in,
    out_file_problem,
    port_offset,
    read_bounded,
    seed,
    zenoh_endpoint,
    zenoh_listen_endpoint,
)
from swarm_common.logsetup import LogLevel, add_log_level_argument, configure_logging
from swarm_common.ports import MAX_ID
from swarm_common.process_life import exit_now, freeze_startup
from swarm_common.scenario.files import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    ScenarioError,
    swarm_name_problem,
)
from swarm_common.signing import SigningKeyError, key_file, load_key
from swarm_common.world.geodesy import MAX_LAT_DEG
from swarm_common.zenoh_session import ZENOH_CONFIG_ENV, ZENOH_CONFIG_FLAG

if TYPE_CHECKING:  # the scenario model and the server load after the flags are checked
    from swarm_common.scenario.spec import Scenario
    from vehicle_sim.options import SimOptions
    from vehicle_sim.server import SimServer

# what :func:`main` imports once the flags are checked: the fork server
# (gcs.launch.preload) imports them before it forks a simulator
RUNTIME_MODULES = (
    "swarm_common.scenario.model",
    "vehicle_sim.autopilot.params",
    "vehicle_sim.link.endpoint",
    "vehicle_sim.options",
    "vehicle_sim.server",
)
log = logging.getLogger("vehicle_sim")
MAX_TIMEOUT_S = 3600.0  # --offboard-timeout, --step-timeout
MAX_RATE_HZ = 5000.0  # --odometry-hz: the highest physics rate a scenario may have
MAX_SIM_DURATION_S = 1e7  # --duration: about 116 days of simulated time
UNSIGNED_WARNING = ("no --signing-key: the vehicles accept unsigned MAVLink commands from "
                    "anyone who reaches their ports (gcs keys generate; docs/security.md)")


MAX_HOME_ALT_M = 9000.0  # --home: AMSL altitudes in [-MAX_HOME_ALT_M / 18, MAX_HOME_ALT_M]


def home_point(text: str) -> tuple[float, float, float]:
    """argparse ``type=`` of ``--home LAT,LON,ALT``: degrees, degrees, metres AMSL (PX4
    SITL's PX4_HOME_LAT/LON/ALT); a latitude within ±85° (the flat-earth conversion)."""
    parts = text.split(",")
    vals = [finite_float(p) for p in parts] if len(parts) == 3 else []
    if len(vals) != 3 or any(v is None for v in vals):
        raise argparse.ArgumentTypeError(f"{text!r}: must be LAT,LON,ALT (three numbers)")
    lat, lon, alt = (float(v) for v in vals if v is not None)
    if not (abs(lat) <= MAX_LAT_DEG and abs(lon) <= 180.0
            and -MAX_HOME_ALT_M / 18 <= alt <= MAX_HOME_ALT_M):
        raise argparse.ArgumentTypeError(
            f"{text!r}: latitude within ±{MAX_LAT_DEG:g}°, longitude within ±180°, altitude "
            f"in [{-MAX_HOME_ALT_M / 18:g}, {MAX_HOME_ALT_M:g}] m")
    return lat, lon, alt


def build_parser() -> argparse.ArgumentParser:
    ap = OneLineParser(
        prog="vehicle-sim",
        description="SITL-style multi-vehicle MAVLink 2 simulator (PX4 conventions).",
    )
    ap.add_argument("--scenario", required=True, type=bounded_file(MAX_SCENARIO_BYTES,
                                                                    "scenario file"),
                    help="scenario TOML file (scenarios/cube8.toml)")
    ap.add_argument("--lockstep", action="store_true", help="advance only when controllers answer")
    ap.add_argument("--seed", type=seed, default=None,
                    help="dynamics seed, 0..2^32-1 (default: scenario)")
    ap.add_argument(ALLOW_INFEASIBLE_FLAG, action="store_true",
                    help="run a scenario that fails the feasibility check, with a warning")
    ap.add_argument(ALLOW_UNSAFE_FLAG, action="store_true",
                    help="run a scenario that breaks a load-time safety assumption, with a "
                    "warning")
    ap.add_argument("--port-offset", type=port_offset, default=0,
                    help="shift every UDP/TCP port")
    ap.add_argument("--bind", type=host, default="127.0.0.1",
                    help="address the vehicle sockets bind")
    ap.add_argument("--remote-host", type=host, default="127.0.0.1",
                    help="where default streams go (an IPv4 address or a host name)")
    ap.add_argument(
        "--swarm", default=None, help="swarm name in the Zenoh keys (default: the scenario name)"
    )
    ap.add_argument("--zenoh-listen", nargs="+", type=zenoh_listen_endpoint, default=[],
                    metavar="EP")
    ap.add_argument("--zenoh-connect", nargs="+", type=zenoh_endpoint, default=[], metavar="EP")
    ap.add_argument("--zenoh-mode", choices=("peer", "client", "router"), default="peer")
    ap.add_argument("--no-zenoh", action="store_true", help="do not publish truth")
    ap.add_argument(ZENOH_CONFIG_FLAG, default=None, metavar="FILE",
                    type=bounded_file(MAX_ZENOH_CONFIG_BYTES, "zenoh config"),
                    help="Zenoh JSON5 config with this process's credentials (as written by "
                    f"gcs router --secure-dir; default: ${ZENOH_CONFIG_ENV} if set)")
    ap.add_argument("--signing-key", default=None, metavar="PATH", type=key_file,
                    help="MAVLink 2 signing key file (gcs keys generate): reject unsigned or "
                    "wrongly signed frames, sign every frame sent (default: signing off)")
    ap.add_argument("--unsigned-gcs-link", action="store_true",
                    help="with --signing-key: let unsigned clients (MAVSDK, QGC) on the GCS "
                    "port read telemetry, parameters and missions; they can never arm, fly, "
                    "switch modes or write")
    ap.add_argument(
        "--failsafe",
        type=str.lower,
        choices=[str(a) for a in FailsafeAction],
        default=str(FailsafeAction.HOLD),
        help="what a vehicle does on offboard loss",
    )
    ap.add_argument("--offboard-timeout", type=float_in(0, MAX_TIMEOUT_S, lo_open=True, unit="s"),
                    default=0.5)
    ap.add_argument("--odometry-hz", type=float_in(0, MAX_RATE_HZ, lo_open=True, unit="Hz"),
                    default=50.0)
    ap.add_argument("--step-timeout", type=float_in(0, MAX_TIMEOUT_S, lo_open=True, unit="s"),
                    default=0.5)
    ap.add_argument("--duration", type=float_in(0, MAX_SIM_DURATION_S, lo_open=True, unit="s"),
                    default=None, help="exit 0 after this much simulated time (s)")
    ap.add_argument("--vehicles", type=int_in(1, MAX_ID), default=None, metavar="K",
                    help="simulate only the first K agents of the scenario")  # fmt: skip
    ap.add_argument(
        "--default-streams", choices=[d.value for d in DefaultStreams],
        default=DefaultStreams.ALWAYS.value,
        help="always: stream the default telemetry to each link's default remote as PX4 "
             "does; on-contact: HEARTBEAT only until a client there speaks (a lockstep "
             "batch run with no ground station pays nothing for telemetry)",
    )
    ap.add_argument(
        "--home", type=home_point, default=None, metavar="LAT,LON,ALT",
        help="the geodetic origin of every vehicle's local frame (degrees, degrees, m AMSL; "
             "default PX4 SITL's, 47.397742,8.545594,488): GPS positions, HOME_POSITION, "
             "GPS_GLOBAL_ORIGIN and the stored fences are about it",
    )
    ap.add_argument(
        "--quiet", action="store_true", help="no event log on stderr (same as --log-level warning)"
    )
    add_log_level_argument(ap)
    ap.add_argument(
        "--stats-out",
        default=None,
        metavar="PATH",
        help="write run statistics (setpoint latency, timeouts) as JSON at exit",
    )
    ap.add_argument(
        "--params-file",
        default=None,
        metavar="PATH",
        type=bounded_file(MAX_PARAMS_BYTES, "parameter file", missing_ok=True),
        help="PX4 parameters per vehicle (JSON, docs/px4/params.md): loaded at start, "
        "rewritten on every accepted PARAM_SET; created if missing",
    )
    return ap


EXIT_USAGE = 2


class _Fatal(Exception):
    """A one-line fatal error: printed as ``vehicle-sim: <line>``, exit 2."""


def _options(args: argparse.Namespace, sc: Scenario) -> SimOptions:
    """Check the options that depend on the scenario and type them."""
    from vehicle_sim.options import SimOptions

    if args.vehicles is not None and not 1 <= args.vehicles <= sc.n:
        raise _Fatal(f"--vehicles {args.vehicles}: must be in [1, {sc.n}]")
    if args.swarm is not None and (problem := swarm_name_problem(args.swarm)) is not None:
        raise _Fatal(f"--swarm {args.swarm!r}: {problem}")
    key = None
    if args.signing_key is not None:
        try:
            key = load_key(args.signing_key)
        except SigningKeyError as exc:
            raise _Fatal(f"--signing-key: {exc}") from None
    elif args.unsigned_gcs_link:
        raise _Fatal("--unsigned-gcs-link needs --signing-key (without a key nothing is signed)")
    return SimOptions(
        signing_key=key,
        unsigned_gcs=args.unsigned_gcs_link,
        default_streams=DefaultStreams(args.default_streams),
        lockstep=args.lockstep,
        seed=args.seed,
        port_offset=args.port_offset,
        bind_host=args.bind,
        remote_host=args.remote_host,
        swarm=args.swarm or sc.name,
        zenoh=not args.no_zenoh,
        zenoh_mode=args.zenoh_mode,
        zenoh_listen=args.zenoh_listen,
        zenoh_connect=args.zenoh_connect,
        failsafe=FailsafeAction(args.failsafe),
        offboard_timeout=args.offboard_timeout,
        odometry_hz=args.odometry_hz,
        step_timeout=args.step_timeout,
        duration=args.duration,
        vehicles=args.vehicles,
        stats_out=args.stats_out,
        params_file=args.params_file,
        home=args.home,
    )


def check_files(args: argparse.Namespace) -> None:
    """What the flags' parse did not check, before anything starts
    (:mod:`swarm_common.inputs`): ``$SWARM_ZENOH_CONFIG`` (without ``--zenoh-config``) is a
    regular file within its cap; ``--stats-out`` and a ``--params-file`` still to be
    created can be written. The file options themselves were checked as they were parsed
    (``bounded_file``). :class:`_Fatal` with one line if not."""
    env_config = os.environ.get(ZENOH_CONFIG_ENV) or None
    if args.zenoh_config is None and not args.no_zenoh and env_config is not None:
        try:
            read_bounded(env_config, MAX_ZENOH_CONFIG_BYTES, "zenoh config")
        except BoundedReadError as exc:
            raise _Fatal(f"${ZENOH_CONFIG_ENV}: {exc}") from None
    if args.params_file is not None and not os.path.lexists(args.params_file):
        if (why := out_file_problem(args.params_file, "--params-file")) is not None:
            raise _Fatal(why)
    if args.stats_out is not None and (why := out_file_problem(args.stats_out,
                                                               "--stats-out")) is not None:
        raise _Fatal(why)


def _server(args: argparse.Namespace) -> SimServer:
    """Load the scenario and open every socket; :class:`_Fatal` with one line if not."""
    from swarm_common.scenario.model import load_scenario
    from swarm_common.scenario.schema import mavlink_id_problem
    from vehicle_sim.link.endpoint import LinkError
    from vehicle_sim.server import SimServer

    check_files(args)
    try:
        sc = load_scenario(args.scenario, args.allow_infeasible, args.allow_unsafe)
    except ScenarioError as exc:
        raise _Fatal(str(exc)) from None
    if (why := mavlink_id_problem(list(sc.ids))) is not None:  # a vehicle is a MAVLink system
        raise _Fatal(f"{sc.path}: {why}")
    opts = _options(args, sc)
    if args.zenoh_config is not None:
        # read by swarm_common.zenoh_session.make_config when the truth session opens
        os.environ[ZENOH_CONFIG_ENV] = args.zenoh_config
    try:
        server = SimServer(sc, opts)
    except LinkError as exc:
        raise _Fatal(str(exc.strerror)) from None
    except (RuntimeError, ValueError) as exc:
        raise _Fatal(str(exc).splitlines()[0]) from None
    try:
        _attach_params_file(server, opts.params_file)
    except _Fatal:
        server.close()
        raise
    if opts.signing_key is None:  # every check passed: one line as the simulator starts
        log.warning("%s", UNSIGNED_WARNING)
    for line in port_map_lines(opts, [v.id for v in server.vehicles]):
        log.info("%s", line)
    return server


def _attach_params_file(server: SimServer, path: str | None) -> None:
    """``--params-file``: validate it, apply it to every vehicle, save on every change."""
    if path is None or not server.vehicles:
        return
    from vehicle_sim.autopilot.params import ParamFile, ParamFileError, read_param_file

    try:
        stored = read_param_file(path, server.vehicles[0].params)
    except ParamFileError as exc:
        raise _Fatal(f"--params-file {path}: {exc}") from None
    pf = ParamFile(path, stored)
    for v in server.vehicles:
        pf.attach(v.id, v.params)
    log.info("parameters: %s (%d vehicles with saved values)", path, len(stored))


def port_map_lines(opts: SimOptions, ids: list[int]) -> list[str]:
    """The ports to connect to (PX4 SITL-style map, swarm_common.ports), one line each."""
    from swarm_common.ports import vehicle_ports
    from swarm_common.zenoh_session import default_endpoint

    host = opts.bind_host
    lines = ["port map (vehicle: sim binds -> streams to):"]
    for aid in ids:
        p = vehicle_ports(aid, opts.port_offset)
        lines.append(
            f"  vehicle {aid} (sysid {aid}): API/offboard udp {host}:{p.api_local} -> "
            f"{opts.remote_host}:{p.api_remote}, GCS udp {host}:{p.gcs_local} -> "
            f"{opts.remote_host}:{p.gcs_remote}"
        )
    if not opts.zenoh:
        lines.append("  zenoh: off (--no-zenoh)")
    else:
        listen = list(opts.zenoh_listen)
        if not listen and not opts.zenoh_connect and opts.zenoh_mode != "client":
            listen = [default_endpoint(opts.port_offset)]
        lines.append(
            f"  zenoh ({opts.zenoh_mode}): listen {', '.join(listen) or '-'}; "
            f"connect {', '.join(opts.zenoh_connect) or '-'}"
        )
    return lines


def _run(server: SimServer) -> int:
    """Run until SIGINT/SIGTERM or ``--duration``; ``VEHICLE_SIM_PROFILE=path`` dumps a
    cProfile of the loop (developer aid; the main thread's CPU time)."""

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        server.stop_requested = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    single_thread_blas()  # tiny matrices: BLAS worker threads only cost (swarm_common.blas)
    prof_path = os.environ.get("VEHICLE_SIM_PROFILE")
    freeze_startup()  # later collections skip the start-up's objects (process_life)
    try:
        if prof_path:
            import cProfile

            log.info("profiling to %s", prof_path)
            prof = cProfile.Profile(time.thread_time)  # the loop's own CPU, not Zenoh's threads
            try:
                return prof.runcall(server.run)
            finally:
                prof.dump_stats(prof_path)
        return server.run()
    finally:
        server.close()


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = LogLevel(args.log_level)
    if args.quiet and level in (LogLevel.DEBUG, LogLevel.INFO):
        level = LogLevel.WARNING
    configure_logging(level)
    try:
        server = _server(args)
    except _Fatal as exc:
        print(f"vehicle-sim: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return _run(server)


if __name__ == "__main__":
    exit_now(main())  # no interpreter teardown (swarm_common.process_life)
