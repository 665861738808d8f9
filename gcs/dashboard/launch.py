"""``gcs dashboard --launch``: start the swarm's processes, stop them on exit.

Topology (as ``gcs mission run``): this process opens a Zenoh router on
``tcp/127.0.0.1:7447+offset``; ``vehicle-sim`` (real time, no ``--lockstep``) listens
on ``7448+offset`` and dials the router; every offboard daemon dials the router in
client mode. The dashboard's own feed uses the router session directly.

:func:`daemon_argv` is the hook for the per-agent offboard daemons: ``--no-daemons``
skips them (then OFFBOARD is refused: nothing streams setpoints).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from gcs.procs import ProcessGroup, python_entry
from gcs.router import open_router
from swarm_common.ports import port_free, swarm_udp_ports
from swarm_common.scenario import Scenario

ZENOH_BASE = 7447


def router_endpoint(offset: int) -> str:
    return f"tcp/127.0.0.1:{ZENOH_BASE + offset}"


def sim_endpoint(offset: int) -> str:
    return f"tcp/127.0.0.1:{ZENOH_BASE + offset + 1}"


def busy_ports(sc: Scenario, offset: int) -> list[str]:
    """Every UDP port the launched swarm will bind, that is already taken."""
    return [f"udp {p}" for p in swarm_udp_ports(sc.ids, offset) if not port_free(p)]


def sim_argv(sc: Scenario, offset: int, swarm: str, zenoh: bool) -> list[str]:
    argv = [
        *python_entry("vehicle_sim.cli"),
        "--scenario",
        sc.path,
        "--port-offset",
        str(offset),
        "--swarm",
        swarm,
    ]
    if zenoh:
        argv += ["--zenoh-listen", sim_endpoint(offset), "--zenoh-connect", router_endpoint(offset)]
    else:
        argv.append("--no-zenoh")
    return argv


def daemon_argv(
    sc: Scenario, agent_id: int, offset: int, swarm: str, method: str | None
) -> list[str]:
    """HOOK: the offboard daemon of one agent, real time, dialling the router."""
    argv = [
        *python_entry("offboard.cli"),
        "--scenario",
        sc.path,
        "--agent",
        str(agent_id),
        "--port-offset",
        str(offset),
        "--swarm",
        swarm,
        "--realtime",
        "--manual-start",  # the operator arms and starts the formation from the dashboard
        "--zenoh-connect",
        router_endpoint(offset),
    ]
    if method:
        argv += ["--method", method]
    return argv


class Launch:
    """The processes ``--launch`` started (and the router session)."""

    def __init__(
        self,
        sc: Scenario,
        offset: int,
        swarm: str,
        log_dir: Path,
        zenoh: bool = True,
        daemons: bool = True,
        method: str | None = None,
    ) -> None:
        self.sc = sc
        self.offset = offset
        self.swarm = swarm
        self.log_dir = log_dir
        self.zenoh = zenoh
        self.daemons = daemons and zenoh
        self.method = method
        self.router: Any = None
        self.group = ProcessGroup(log_dir)

    def start(self) -> Launch:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        if self.zenoh:
            self.router = open_router([router_endpoint(self.offset)])
        self.group.start("vehicle-sim", sim_argv(self.sc, self.offset, self.swarm, self.zenoh))
        if self.daemons:
            for a in self.sc.agents:
                self.group.start(
                    f"offboard-{a.id}",
                    daemon_argv(self.sc, a.id, self.offset, self.swarm, self.method),
                )
        return self

    def dead(self) -> list[str]:
        return [f"{c.name} (exit {c.proc.returncode}, log {c.log_path})" for c in self.group.dead()]

    def wait_sim_up(self, timeout_s: float = 10.0) -> str | None:
        """None once vehicle-sim is running after a short grace, else why it is not."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            sim = self.group.children[0]
            if sim.proc.poll() is not None:
                return (
                    f"vehicle-sim exited with code {sim.proc.returncode}:\n{self.group.tail(sim)}"
                )
            if time.monotonic() > deadline - timeout_s + 1.0:
                return None
            time.sleep(0.05)
        return None

    def stop(self) -> None:
        self.group.stop()
        if self.router is not None:
            try:
                self.router.close()
            except Exception:
                pass
            self.router = None
