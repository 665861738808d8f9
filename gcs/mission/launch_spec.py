"""What a launched swarm is: ports, Zenoh endpoints and the command line of every process.

One :class:`LaunchSpec` is used by ``gcs mission run``/``compare`` (lockstep by default,
recording a run directory) and by ``gcs dashboard --launch`` (real time, the operator
arms and starts). Topology, for port offset ``o``:

* the ``gcs`` process hosts the Zenoh router on ``tcp/127.0.0.1:7447+o``
  (:data:`~swarm_common.zenoh_session.DEFAULT_ZENOH_PORT`);
* ``vehicle-sim`` listens on ``7448+o`` and dials the router;
* one ``offboard`` daemon per agent dials the router in client mode, or with
  ``processes`` = P the agents packed into P ``offboard --agents A-B`` processes
  (contiguous ids, as even as possible; :mod:`offboard.daemon.host`);
* MAVLink runs over the UDP ports of :mod:`swarm_common.ports`.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs.launch.watchdog import remove_on_death
from gcs.mission.ports import (
    PortUse,
    busy_uses,
    port_in_use_line,
    swarm_port_uses,
)
from gcs.mission.procs import python_entry
from offboard.daemon.packing import format_agents
from swarm_common.enums import DefaultStreams
from swarm_common.ports import GCS_PORT, MAX_ID, vehicle_ports
from swarm_common.scenario.model import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    Scenario,
    swarm_name_problem,
)
from swarm_common.signing import generate_key, key_file, load_key
from swarm_common.zenoh_session import (
    DEFAULT_ZENOH_PORT,
    SIM_USER,
    ZENOH_CONFIG_ENV,
    SwarmSecurity,
    pack_user,
)

LOCALHOST = "127.0.0.1"
# > the daemons' neighbour timeout (0.45 s): in lockstep a dead agent costs one wait
LOCKSTEP_STEP_TIMEOUT_S = 1.0


def _max_port_offset() -> int:
    vp = [vehicle_ports(i, 0) for i in range(1, MAX_ID + 1)]
    highest = max(max(p.api_local, p.api_remote, p.gcs_local, p.gcs_remote) for p in vp)
    highest = max(highest, DEFAULT_ZENOH_PORT + 1, GCS_PORT)
    return 65535 - highest


class LaunchError(RuntimeError):
    """The swarm cannot start here: a port is busy or an endpoint is refused (exit 2)."""


RUN_KEY_NAME = "mavlink.key"  # the per-run signing key, inside the run's secure directory


def secure_dir() -> Path:
    """A fresh private directory (mode 0700) for one run's Zenoh credentials and signing
    key; the caller deletes it with :func:`gcs.launch.watchdog.release_dir` when the run ends.
    A watchdog process deletes it if this process dies first, kill -9 included
    (:func:`gcs.launch.watchdog.remove_on_death`): no secret outlives its run."""
    path = Path(tempfile.mkdtemp(prefix="swarm-secure-"))
    try:
        remove_on_death(path)
    except OSError:
        shutil.rmtree(path, ignore_errors=True)
        raise
    return path


def split_packs(ids: list[int], processes: int | None) -> list[list[int]]:
    """``ids`` in ``processes`` contiguous groups whose sizes differ by at most one (None:
    one group per agent); :class:`LaunchError` (one line) unless 1 ≤ processes ≤ agents."""
    n = len(ids) if processes is None else processes
    if not 1 <= n <= len(ids):
        raise LaunchError(f"--processes {n}: must be 1..{len(ids)} (the number of agents)")
    size, extra = divmod(len(ids), n)
    out, at = [], 0
    for p in range(n):
        take = size + (1 if p < extra else 0)
        out.append(ids[at:at + take])
        at += take
    return out


@dataclass(frozen=True)
class SigningChoice:
    """MAVLink 2 signing of a launched swarm (docs/security.md, "Defaults").

    ``enabled`` (default): every vehicle link is signed; with ``key`` (a key file made by
    ``gcs keys generate``) that key, else a fresh per-run key written into the run's
    secure directory. ``unsigned_gcs_link``: the simulator's GCS port also serves unsigned
    telemetry requests (MAVSDK, QGroundControl), never flight commands.
    """

    enabled: bool = True
    key: Path | None = None
    unsigned_gcs_link: bool = False
    def __post_init__(self) -> None:
        if not self.enabled and self.key is not None:
            raise LaunchError("--no-signing and --signing-key exclude each other")
        if self.key is not None:  # a bad key file stops here, before ports or processes
            load_key(self.key)  # SigningKeyError (a ValueError): one line
        if not self.enabled and self.unsigned_gcs_link:
            raise LaunchError("--unsigned-gcs-link needs signing (drop --no-signing)")

    @classmethod
    def from_args(cls, args: Any) -> SigningChoice:
        """From ``--no-signing``, ``--signing-key PATH``, ``--unsigned-gcs-link``."""
        key = getattr(args, "signing_key", None)
        return cls(
            enabled=not getattr(args, "no_signing", False),
            key=None if key is None else Path(key).absolute(),
            unsigned_gcs_link=bool(getattr(args, "unsigned_gcs_link", False)),
        )

    def key_file(self, directory: Path | None) -> Path | None:
        """The key file the children get: None when signing is off; the user's file (checked
        now, so a bad one stops the launch with one line); else a fresh key generated as
        ``directory/mavlink.key`` (0600). Raises ``SigningKeyError`` (a ValueError)."""
        if not self.enabled:
            return None
        if self.key is not None:
            load_key(self.key)
            return self.key
        if directory is None:
            raise LaunchError("signing needs a private directory for the per-run key")
        path = directory / RUN_KEY_NAME
        generate_key(path)
        return path

    def describe(self) -> str:
        """For the run facts: ``off``, ``per-run key`` or ``key file`` (never the key)."""
        if not self.enabled:
            return "off"
        return "per-run key" if self.key is None else "key file"


@dataclass(frozen=True)
class LaunchSpec:
    """Ports, endpoints and argv of one launched swarm.

    ``lockstep``: the simulator waits for every controller (mission runs); otherwise all
    processes run on the wall clock. ``manual_start``: the daemons stream setpoints but
    leave arming and OFFBOARD to the operator (dashboard). ``run_dir``: where each
    daemon writes its ``vehicle_<id>.tlog`` and the simulator its statistics.
    ``sim_duration``: the simulator exits after this much simulated time (s).
    ``zenoh_security``: the router's credentials, one file per child (docs/security.md).
    ``signing_key``: the MAVLink 2 signing key file given to the simulator and every daemon
    (``--signing-key``); ``unsigned_gcs_link``: the simulator's GCS link also serves
    unsigned telemetry requests (MAVSDK, QGroundControl without a key).
    ``daemon_processes``: pack the daemons into this many processes (None: one per agent, the
    realistic layout); a packed process holds one Zenoh session for several agents and
    authenticates as one user allowed to publish its own agents' keys only
    (:func:`~swarm_common.zenoh_session.pack_user`). ``default_streams``: the simulator's
    ``--default-streams`` (``on-contact``: a lockstep batch run with no ground station
    listening pays nothing for the vehicles' default telemetry).
    """

    sc: Scenario
    port_offset: int = 0
    swarm: str | None = None
    method: str | None = None
    seed: int | None = None
    lockstep: bool = True
    zenoh: bool = True
    manual_start: bool = False
    run_dir: Path | None = None
    sim_duration: float | None = None
    zenoh_security: SwarmSecurity | None = None
    signing_key: Path | None = None
    unsigned_gcs_link: bool = False
    daemon_processes: int | None = None
    # the simulator's --default-streams (vehicle_sim: telemetry to a silent default remote)
    default_streams: DefaultStreams = DefaultStreams.ALWAYS

    def __post_init__(self) -> None:
        self.packs()  # validates daemon_processes (split_packs)
        problem = swarm_name_problem(self.swarm_name)
        if problem is not None:
            raise LaunchError(f"swarm name {self.swarm_name!r}: {problem}")
        if self.port_offset < 0 or self.port_offset > MAX_PORT_OFFSET:
            raise LaunchError(f"port offset {self.port_offset}: must be 0..{MAX_PORT_OFFSET}")
        if self.unsigned_gcs_link and self.signing_key is None:
            raise LaunchError("--unsigned-gcs-link needs signing (without a key nothing is signed)")

    @property
    def swarm_name(self) -> str:
        """The swarm name in the Zenoh keys (default: the scenario name)."""
        return self.swarm or self.sc.name

    @property
    def router_port(self) -> int:
        return DEFAULT_ZENOH_PORT + self.port_offset

    @property
    def sim_port(self) -> int:
        return DEFAULT_ZENOH_PORT + self.port_offset + 1

    @property
    def router_endpoint(self) -> str:
        return f"tcp/{LOCALHOST}:{self.router_port}"

    @property
    def sim_endpoint(self) -> str:
        return f"tcp/{LOCALHOST}:{self.sim_port}"

    @property
    def sim_stats_path(self) -> Path | None:
        return None if self.run_dir is None else self.run_dir / "vehicle-sim-stats.json"

    def port_uses(self, gcs_port: bool = False) -> list[PortUse]:
        """Every port this swarm binds (:func:`gcs.mission.ports.swarm_port_uses`).
        ``gcs_port``: also the GCS port (14550+offset), which only a ground station (the
        dashboard) binds; a mission run leaves it to whoever listens there."""
        return swarm_port_uses(self.sc.ids, self.port_offset, self.zenoh, gcs_port)

    def busy_ports(self, gcs_port: bool = False) -> list[str]:
        """Every port the swarm will bind that is already taken, as ``"udp 14580
        (127.0.0.1, vehicle 1 simulator API port)"`` (each bound and released)."""
        return [u.line() for u in busy_uses(self.port_uses(gcs_port))]

    def check_ports(self, gcs_port: bool = False) -> None:
        """Raise :class:`LaunchError`, one line naming the first busy port of this swarm
        (and how many more are busy)."""
        busy = busy_uses(self.port_uses(gcs_port))
        if busy:
            raise LaunchError(port_in_use_line(busy))

    def child_ports(self, name: str) -> list[PortUse]:
        """The ports child ``name`` binds (:meth:`processes`): the simulator its Zenoh
        listener and every vehicle's two links; a daemon its agents' API ports."""
        uses = self.port_uses()
        if name == "vehicle-sim":
            return [u for u in uses if u.role == "Zenoh simulator" or "simulator" in u.role]
        ids = next((p for p in self.packs() if self.daemon_name(p) == name), [])
        return [u for u in uses if u.role in {f"agent {i} API port" for i in ids}]

    def sim_argv(self) -> list[str]:
        """``vehicle-sim`` for this swarm."""
        argv = [
            *python_entry("vehicle_sim.cli"),
            "--scenario", self.sc.path,
            "--port-offset", str(self.port_offset),
            "--swarm", self.swarm_name,
        ]  # fmt: skip
        if self.zenoh:
            argv += ["--zenoh-listen", self.sim_endpoint, "--zenoh-connect", self.router_endpoint]
        else:
            argv.append("--no-zenoh")
        if self.sim_duration is not None:
            argv += ["--duration", f"{self.sim_duration}"]
        if self.sim_stats_path is not None:
            argv += ["--stats-out", str(self.sim_stats_path)]
        if self.lockstep:
            argv += ["--step-timeout", f"{LOCKSTEP_STEP_TIMEOUT_S}", "--lockstep"]
        if self.unsigned_gcs_link:
            argv.append("--unsigned-gcs-link")
        if self.default_streams is not DefaultStreams.ALWAYS:
            argv += ["--default-streams", self.default_streams.value]
        return argv + self._signing_args() + self._common_args()

    def packs(self) -> list[list[int]]:
        """The agents of each daemon process: one each, or :attr:`daemon_processes` contiguous
        groups whose sizes differ by at most one."""
        return split_packs(list(self.sc.ids), self.daemon_processes)

    @staticmethod
    def daemon_name(ids: list[int]) -> str:
        """``offboard-3`` for one agent, ``offboard-3-8`` for a packed process."""
        return f"offboard-{format_agents(ids)}"

    def daemon_argv(self, agent_id: int | list[int]) -> list[str]:
        """The ``offboard`` process of one agent (or of several packed), dialling the
        router."""
        ids = [agent_id] if isinstance(agent_id, int) else list(agent_id)
        who = ["--agent", str(ids[0])] if len(ids) == 1 else ["--agents", format_agents(ids)]
        tlog = f"vehicle_{ids[0]}.tlog" if len(ids) == 1 else "vehicle_{id}.tlog"
        argv = [
            *python_entry("offboard"),
            "--scenario", self.sc.path,
            *who,
            "--port-offset", str(self.port_offset),
            "--swarm", self.swarm_name,
            "--zenoh-connect", self.router_endpoint,
            "--die-with-parent",
        ]  # fmt: skip
        if self.method:
            argv += ["--method", str(self.method)]
        if self.run_dir is not None:
            argv += ["--tlog", str(self.run_dir / tlog)]
        if not self.lockstep:
            argv.append("--realtime")
        if self.manual_start:
            argv.append("--manual-start")
        return argv + self._signing_args() + self._common_args()

    @staticmethod
    def is_daemon(name: str) -> bool:
        """True for the name of a daemon process (:meth:`daemon_name`)."""
        return name.startswith("offboard-")

    def child_env(self, name: str) -> dict[str, str]:
        """Extra environment of child ``name``: with :attr:`zenoh_security`, the path of
        its own Zenoh config (credentials) in ``$SWARM_ZENOH_CONFIG``, read by
        :func:`~swarm_common.zenoh_session.open_session`; the password never appears in
        an argv or a log."""
        if self.zenoh_security is None:
            return {}
        if name == "vehicle-sim":
            user = SIM_USER
        else:
            user = next(pack_user(ids) for ids in self.packs() if self.daemon_name(ids) == name)
        return {ZENOH_CONFIG_ENV: str(self.zenoh_security.config_for(user))}

    def processes(self, daemons: bool = True) -> list[tuple[str, list[str]]]:
        """``(name, argv)`` of every child, simulator first; the daemons (which need Zenoh)
        unless ``daemons`` is False."""
        out = [("vehicle-sim", self.sim_argv())]
        if daemons and self.zenoh:
            out += [(self.daemon_name(ids), self.daemon_argv(ids)) for ids in self.packs()]
        return out

    def _signing_args(self) -> list[str]:
        """``--signing-key PATH`` when the swarm's MAVLink links are signed (the path, never
        the key, is in the argv)."""
        return [] if self.signing_key is None else ["--signing-key", str(self.signing_key)]

    def _common_args(self) -> list[str]:
        """``--seed`` if set; ``--allow-infeasible`` and ``--allow-unsafe`` if the scenario was
        loaded with them."""
        argv = [] if self.seed is None else ["--seed", str(self.seed)]
        argv += [ALLOW_INFEASIBLE_FLAG] if self.sc.allow_infeasible else []
        return argv + ([ALLOW_UNSAFE_FLAG] if self.sc.allow_unsafe else [])


MAX_PORT_OFFSET = _max_port_offset()


def add_signing_flags(g: Any, launch_note: str = "") -> None:
    """``--signing-key``, ``--no-signing``, ``--unsigned-gcs-link`` (docs/security.md,
    "Defaults"): a launched swarm's MAVLink links are signed unless ``--no-signing``.
    ``launch_note`` prefixes the help of the two launch-only flags (e.g. "with --launch: ")."""
    g.add_argument("--signing-key", default=None, metavar="PATH", type=key_file,
                   help="MAVLink 2 signing key file (gcs keys generate): sign commands, accept "
                   "only signed frames (launched swarm: default a fresh per-run key)")
    g.add_argument("--no-signing", action="store_true",
                   help=f"{launch_note}no MAVLink signing (debugging, or unsigned clients)")
    g.add_argument("--unsigned-gcs-link", action="store_true",
                   help=f"{launch_note}let unsigned clients (MAVSDK, QGC) request telemetry on "
                   "the GCS port; they can never arm, fly or switch modes")
