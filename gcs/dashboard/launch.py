"""``gcs dashboard --launch``: start the swarm's processes, stop them on exit.

Topology and command lines are :class:`gcs.launch_spec.LaunchSpec`'s, as for
``gcs mission run``, but on the wall clock: ``vehicle-sim`` without ``--lockstep`` and
every offboard daemon with ``--realtime --manual-start`` (the operator arms and starts
the formation from the dashboard). This process hosts the Zenoh router; the dashboard's
own feed uses the router session directly. ``--no-daemons`` skips the daemons (then
OFFBOARD is refused: nothing streams setpoints).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import zenoh

from gcs.launch_spec import LaunchError, LaunchSpec
from gcs.procs import ProcessGroup
from gcs.router import open_router
from swarm_common.scenario import Scenario

log = logging.getLogger(__name__)


def dashboard_spec(
    sc: Scenario, offset: int, swarm: str | None, zenoh: bool, method: str | None
) -> LaunchSpec:
    """The launch spec of ``--launch``: real time, manual start, no run directory."""
    return LaunchSpec(
        sc, offset, swarm=swarm, method=method, lockstep=False, zenoh=zenoh, manual_start=True
    )


class Launch:
    """The processes ``--launch`` started (and the router session)."""

    def __init__(self, spec: LaunchSpec, log_dir: Path, daemons: bool = True) -> None:
        self.spec = spec
        self.log_dir = log_dir
        self.daemons = daemons and spec.zenoh
        self.router: Any = None
        self.group = ProcessGroup(log_dir)

    def start(self) -> Launch:
        """Check the ports (the GCS port too: the dashboard binds it), open the router,
        start the children. Raises :class:`~gcs.launch_spec.LaunchError` (nothing left
        running) when a port is busy or the router cannot listen."""
        self.spec.check_ports(gcs_port=True)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        if self.spec.zenoh:
            try:
                self.router = open_router([self.spec.router_endpoint])
            except (RuntimeError, ValueError) as exc:
                raise LaunchError(str(exc)) from None
        try:
            for name, argv in self.spec.processes(daemons=self.daemons):
                self.group.start(name, argv)
        except BaseException:
            self.stop()
            raise
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
            except zenoh.ZError as exc:
                log.warning("closing the Zenoh router: %s", exc)
            self.router = None
