"""``gcs dashboard``: argument parsing and wiring (hooks for ``gcs/cli.py``).

    gcs dashboard [--scenario S] [--port-offset N] [--swarm NAME] [--zenoh-connect EP ...]
    gcs dashboard --launch scenarios/cube8.toml [--no-daemons] [--method rcbf]
    gcs dashboard --demo            # the recorded state, no network (docs, trying keys)
    gcs dashboard --replay RUN      # play a recorded run (run folder or record.mcap)

``--launch`` secures the swarm as ``gcs mission run`` does (docs/security.md, "Defaults"):
Zenoh authentication + ACL with fresh credentials, and MAVLink 2 signing with a fresh key
(or ``--signing-key PATH``; ``--no-signing`` to turn it off) that the dashboard's own GCS
link signs its commands with. Attached to a running swarm, the GCS link signs when given
``--signing-key`` and the Zenoh feed authenticates with ``--zenoh-config FILE``.

``gcs/cli.py`` wires it with::

    from gcs.dashboard.cli import add_dashboard_parser, run_dashboard
    add_dashboard_parser(subparsers)   # sets defaults func=run_dashboard
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gcs.mission.launch_spec import add_signing_flags
from gcs.records.live_flags import add_live_flags, live_endpoint
from swarm_common.enums import Method
from swarm_common.inputs import (
    MAX_SCENARIO_BYTES,
    MAX_ZENOH_CONFIG_BYTES,
    OneLineParser,
    bounded_file,
    float_in,
    int_in,
    out_dir_arg,
    port_offset,
    zenoh_endpoint,
)
from swarm_common.logsetup import add_log_level_argument, configure_logging
from swarm_common.scenario.model import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    ScenarioError,
    load_scenario,
)
from swarm_common.scenario.schema import mavlink_id_problem
from swarm_common.signing import load_key
from swarm_common.zenoh_session import ZENOH_CONFIG_FLAG, default_endpoint

if TYPE_CHECKING:  # loaded by build(), once the flags are checked
    from gcs.formation.steer import FormationSteer

DEFAULT_SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "cube8.toml"


MAX_ACK_TIMEOUT_S = 60.0
MAX_RETRIES = 100


def configure_parser(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("--scenario", default=None,
                   type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"),
                   help="scenario TOML (default scenarios/cube8.toml)")
    p.add_argument("--port-offset", type=port_offset, default=None,
                   help="shift every port by N (default: with --launch the first offset whose "
                   "ports are all free, else 0)")
    p.add_argument(
        "--swarm",
        default=None,
        help="swarm name in the Zenoh keys (default: the scenario name)",
    )
    p.add_argument(
        "--zenoh-connect",
        nargs="+",
        type=zenoh_endpoint,
        default=None,
        metavar="EP",
        help=f"Zenoh endpoints to dial (default {default_endpoint()}+offset)",
    )
    p.add_argument("--zenoh-mode", choices=("client", "peer"), default="client")
    p.add_argument("--no-zenoh", action="store_true", help="MAVLink only")
    p.add_argument(ZENOH_CONFIG_FLAG, default=None, metavar="FILE",
                   type=bounded_file(MAX_ZENOH_CONFIG_BYTES, "zenoh config"),
                   help="attached: Zenoh config with the gcs credentials (gcs router --secure-dir)")
    add_signing_flags(p, "with --launch: ")
    add_live_flags(p)
    p.add_argument(
        "--launch",
        metavar="SCENARIO",
        default=None,
        type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"),
        help="start vehicle-sim (real time) and the offboard daemons; stop on exit",
    )
    p.add_argument("--no-daemons", action="store_true", help="with --launch: simulator only")
    p.add_argument("--formation-vehicle", action="store_true",
                   help="serve the formation as one MAVLink vehicle (system 200, UDP "
                   "14560+offset; a scenario with a [mission], Zenoh on)")
    p.add_argument(
        ALLOW_INFEASIBLE_FLAG,
        action="store_true",
        help="run a scenario that fails the feasibility check (docs/scenarios.md) with a warning",
    )
    p.add_argument(
        ALLOW_UNSAFE_FLAG,
        action="store_true",
        help="run a scenario that breaks a load-time safety assumption (docs/safety.md) with "
        "a warning",
    )
    p.add_argument(
        "--method",
        choices=[str(m) for m in Method],
        default=None,
        help="with --launch: the daemons' initial method",
    )
    p.add_argument("--log-dir", type=out_dir_arg, default=None,
                   help="with --launch: child logs (default: temp)")
    p.add_argument("--ack-timeout", type=float_in(0.0, MAX_ACK_TIMEOUT_S, lo_open=True, unit="s"),
                   default=1.0, help="COMMAND_ACK wait per try (s)")
    p.add_argument("--retries", type=int_in(0, MAX_RETRIES), default=2,
                   help="COMMAND_LONG retries")
    p.add_argument("--demo", action="store_true", help="show the recorded state, no network")
    p.add_argument("--replay", metavar="RUN", default=None,
                   help="play a recorded run (run folder or record.mcap; --scenario: its "
                   "scenario, default scenarios/<name>.toml); no network")
    return p


def add_dashboard_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``dashboard`` on ``gcs``'s subparsers; sets ``func=run_dashboard``."""
    p = subparsers.add_parser(
        "dashboard",
        help="terminal ground station (Textual)",
        description="Terminal ground station: attach to a running swarm, or --launch one.",
    )
    configure_parser(p)
    p.set_defaults(func=run_dashboard)
    return p


def _err(msg: str) -> int:
    print(f"gcs dashboard: {msg}", file=sys.stderr)
    return 2


def build(args: argparse.Namespace) -> tuple[Any, Any, Any, Any]:
    """(app, source, launch, title) from parsed args; raises ValueError/OSError/RuntimeError."""
    from gcs.formation.steer import FormationSteer
    from gcs.mission.launch_spec import SigningChoice
    from gcs.records.live import start_live

    from .app import DashboardApp
    from .commands import LiveCommander
    from .launch import Launch, dashboard_spec
    from .mavlink_gcs import MavlinkGcs
    from .view.preflight import CHECKED_PARAMS, plan_envelope
    from .view.recorded import recorded_source
    from .view.state import LiveSource
    from .zenoh_feed import ZenohFeed

    if args.foxglove and (args.replay or args.demo):
        raise ValueError("--foxglove serves a live swarm; not with --replay or --demo "
                         "(open the run's record.mcap in Foxglove instead)")
    if args.replay:  # a recorded run: RecordError (a ValueError), exit 2 before the app
        from .replay_app import build_replay

        return build_replay(args)
    if args.demo:
        return DashboardApp(recorded_source(), None, title="demo (recorded)"), None, None, None
    live_endpoint(args)  # before the scenario's and the port choice's warnings: one line
    path = args.launch or args.scenario or str(DEFAULT_SCENARIO)
    sc = load_scenario(path, allow_infeasible=args.allow_infeasible,
                       allow_unsafe=args.allow_unsafe)
    if (why := mavlink_id_problem(list(sc.ids))) is not None:  # it watches MAVLink vehicles
        raise ValueError(why)
    offset = 0 if args.port_offset is None else args.port_offset
    if args.launch:  # free ports (or the forced offset's, checked): LaunchError, exit 2
        from gcs.formation.vehicle import FORMATION_PORT
        from gcs.mission.preflight import resolve_port_offset

        base = FORMATION_PORT if args.formation_vehicle else None
        offset = resolve_port_offset(sc, args.port_offset, base, gcs_port=True)
    if args.formation_vehicle and (sc.mission is None or args.no_zenoh):
        raise ValueError("--formation-vehicle needs a scenario with a [mission] and Zenoh")
    if args.foxglove and args.no_zenoh:
        raise ValueError("--foxglove needs the Zenoh feed (not --no-zenoh)")
    live = start_live(args, sc, str(args.method or sc.controller.method), None)
    launch = None
    link = feed = None
    signing = SigningChoice.from_args(args)  # LaunchError (a RuntimeError): exit 2
    try:
        swarm = args.swarm or sc.name
        key_path = signing.key
        if args.launch:
            spec = dashboard_spec(sc, offset, swarm, not args.no_zenoh, args.method)
            log_dir = Path(args.log_dir or tempfile.mkdtemp(prefix="gcs-dashboard-"))
            launch = Launch(spec, log_dir, daemons=not args.no_daemons, signing=signing).start()
            key_path = launch.signing_key
            why = launch.wait_sim_up()
            if why:
                raise RuntimeError(why)
        key = None if key_path is None else load_key(key_path)  # SigningKeyError: ValueError
        link = MavlinkGcs(port_offset=offset, signing_key=key)
        link.param_names = CHECKED_PARAMS  # the pre-flight panel's comparison
        link.start()
        if not args.no_zenoh:
            if launch is not None:
                feed = ZenohFeed(swarm, sc.ids, session=launch.router).start()
            else:
                connect = args.zenoh_connect or [default_endpoint(offset)]
                feed = ZenohFeed(swarm, sc.ids, connect=connect, mode=args.zenoh_mode,
                                 config_file=args.zenoh_config).start()
            if live is not None:  # --foxglove: the live view shows each truth received
                from gcs.mission.live_feed import feed_hook

                feed.on_truth = feed_hook(sc, live, feed.snapshot)
    except BaseException:
        if link is not None:
            link.close()
        if launch is not None:
            launch.stop()
        raise
    source = LiveSource(sc, link, feed, swarm=swarm, procs=launch)
    commander = LiveCommander(link, feed, timeout_s=args.ack_timeout, retries=args.retries)
    title = f"{sc.name} · offset {offset}" + (" · launched" if launch else "")
    title += " · signed" if link.signed else ""
    steer = FormationSteer(sc) if sc.mission is not None else None
    formation = None
    if args.formation_vehicle:
        try:
            formation = _formation_link(sc, feed, steer, offset, key)
        except BaseException:
            source.close()
            if launch is not None:
                launch.stop()
            raise
        title += f" · formation vehicle {formation.port}"
    app = DashboardApp(source, commander, title=title, steer=steer, world=sc.world,
                       formation=formation, preflight=plan_envelope(sc))
    return app, source, launch, title


def _formation_link(sc: Any, feed: Any, steer: FormationSteer | None, offset: int,
                    key: bytes | None) -> Any:
    """The formation vehicle (gcs.dashboard.formation_link); OSError when its port is busy.
    :func:`build` refused a scenario without a mission, or no Zenoh, before starting."""
    from gcs.formation.vehicle import FORMATION_PORT

    from .formation_link import FormationLink

    assert steer is not None and feed is not None  # checked in build, before any work
    try:
        return FormationLink(sc, feed, steer, FORMATION_PORT + offset, key)
    except OSError as exc:
        raise OSError(f"formation vehicle on UDP {FORMATION_PORT + offset}: {exc}") from None


def run_dashboard(args: argparse.Namespace) -> int:
    """Entry point of ``gcs dashboard``: returns the process exit code."""
    try:
        app, source, launch, _ = build(args)
    except ScenarioError as exc:
        return _err(str(exc))
    except (OSError, RuntimeError, ValueError) as exc:
        return _err(str(exc).strip())
    try:
        app.run()
    finally:
        if getattr(app, "formation", None) is not None:
            app.formation.close()
        if source is not None:
            source.close()
        if launch is not None:
            t0 = time.monotonic()
            launch.stop()
            print(
                f"gcs dashboard: stopped launched processes in {time.monotonic() - t0:.1f} s "
                f"(logs in {launch.log_dir})",
                file=sys.stderr,
            )
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m gcs.dashboard`` (the same as ``gcs dashboard``)."""
    p = configure_parser(OneLineParser(prog="gcs dashboard"))
    add_log_level_argument(p)
    args = p.parse_args(argv)
    configure_logging(args.log_level)
    return run_dashboard(args)
