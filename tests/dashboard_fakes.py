"""A fake dashboard commander (the app's command side without MAVLink or Zenoh), shared by
the headless dashboard tests of land-all and take-off."""

from __future__ import annotations

from gcs.dashboard.mavlink_gcs import CommandResult
from gcs.dashboard.px4modes import COMMANDS
from swarm_common.wire import Command


class FakeCommander:
    """Records every MAVLink and Zenoh command; ``refuse``: the vehicle whose arm fails;
    ``t``: the swarm's mission time (s) it reports; ``up``: whether Zenoh is up."""

    def __init__(self, up: bool = True, t: float | None = 4.0, refuse: int = 0) -> None:
        self.up, self.t, self.refuse = up, t, refuse
        self.mav_calls: list[tuple[int, str]] = []
        self.zenoh_calls: list[Command] = []

    async def mav(self, sysid: int, key: str) -> CommandResult:
        self.mav_calls.append((sysid, key))
        spec = COMMANDS[key]
        result = 4 if sysid == self.refuse and key == "arm" else 0  # 4: MAV_RESULT_FAILED
        return CommandResult(sysid, spec.command, spec.label, result, 1, 0.01)

    def zenoh(self, cmd: Command) -> str:
        self.zenoh_calls.append(cmd)
        return f"swarm/test/cmd/{cmd.kind}"

    def zenoh_up(self) -> bool:
        return self.up

    def mission_time(self) -> float | None:
        return self.t
