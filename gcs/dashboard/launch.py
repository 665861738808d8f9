"""``gcs dashboard --launch``: start the swarm's processes, stop them on exit.

Topology and command lines are :class:`gcs.mission.launch_spec.LaunchSpec`'s, as for
``gcs mission run``, but on the wall clock: ``vehicle-sim`` without ``--lockstep`` and
every offboard daemon with ``--realtime --manual-start`` (the operator arms and starts
the formation from the dashboard). This process hosts the Zenoh router; the dashboard's
own feed uses the router session directly. ``--no-daemons`` skips the daemons (then
OFFBOARD is refused: nothing streams setpoints).

Security defaults as for ``gcs mission run`` (docs/security.md, "Defaults"): a private
directory (0700, deleted by :meth:`Launch.stop`) holds fresh Zenoh credentials (the router
authenticates every child and enforces the ACL) and, unless ``--no-signing`` or
``--signing-key PATH``, a fresh MAVLink signing key that the simulator, every daemon and
the dashboard's own GCS link use.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Any

import zenoh

from gcs.launch.watchdog import release_dir
from gcs.mission.launch_spec import LaunchError, LaunchSpec, SigningChoice, secure_dir
from gcs.mission.procs import ProcessGroup
from gcs.mission.router import open_router
from swarm_common.scenario.model import Scenario
from swarm_common.zenoh_session import write_swarm_security

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

    def __init__(
        self,
        spec: LaunchSpec,
        log_dir: Path,
        daemons: bool = True,
        signing: SigningChoice | None = None,
        secure: bool = True,
    ) -> None:
        self.spec = spec
        self.log_dir = log_dir
        self.daemons = daemons and spec.zenoh
        self.signing = SigningChoice() if signing is None else signing
        self.secure = secure and spec.zenoh
        self.secure_dir: Path | None = None
        self.router: Any = None
        self.group = ProcessGroup(log_dir)

    @property
    def signing_key(self) -> Path | None:
        """The key file every launched process signs with (None: signing off)."""
        return self.spec.signing_key

    def start(self) -> Launch:
        """Check the ports (the GCS port too: the dashboard binds it), write the run's
        credentials and key, open the router, start the children. Raises
        :class:`~gcs.mission.launch_spec.LaunchError` (nothing left running, the private directory
        deleted) when a port is busy, a key is refused or the router cannot listen."""
        self.spec.check_ports(gcs_port=True)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        try:
            self._secure_spec()
            if self.spec.zenoh:
                sec = self.spec.zenoh_security
                self.router = open_router([self.spec.router_endpoint],
                                          config_file=None if sec is None else sec.router)
        except (RuntimeError, ValueError, OSError) as exc:  # SigningKeyError: a ValueError
            self.stop()
            raise LaunchError(str(exc)) from None
        try:
            for name, argv in self.spec.processes(daemons=self.daemons):
                self.group.start(name, argv, env=self.spec.child_env(name),
                                 gated=self.spec.is_daemon(name))
        except BaseException:
            self.stop()
            raise
        return self

    def _secure_spec(self) -> None:
        """Fresh Zenoh credentials and (unless signing is off or a key file was given) a
        fresh signing key in a private directory; the spec gets both."""
        if self.secure or (self.signing.enabled and self.signing.key is None):
            self.secure_dir = secure_dir()
        sec = None
        if self.secure and self.secure_dir is not None:
            sec = write_swarm_security(self.secure_dir, self.spec.swarm_name, self.spec.sc.ids)
        key = self.signing.key_file(self.secure_dir)
        self.spec = dataclasses.replace(
            self.spec, zenoh_security=sec, signing_key=key,
            unsigned_gcs_link=self.signing.unsigned_gcs_link,
        )

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
        """Stop the children, close the router, delete the private directory (the
        passwords and the per-run key die with the launch)."""
        self.group.stop()
        if self.router is not None:
            try:
                self.router.close()
            except zenoh.ZError as exc:
                log.warning("closing the Zenoh router: %s", exc)
            self.router = None
        if self.secure_dir is not None:
            release_dir(self.secure_dir)
            self.secure_dir = None
