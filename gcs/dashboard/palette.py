"""The dashboard's command palette (ctrl+p): every key's action, for the selected vehicle
or for all.

Entry point: :func:`palette_commands`, which :class:`~gcs.dashboard.app.DashboardApp`
yields after Textual's own commands.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Protocol

from textual.app import SystemCommand

from swarm_common.wire import Command

from .px4modes import COMMANDS
from .zenoh_feed import METHODS

OUTAGES_S = (0.5, 1.0, 2.0, 5.0)  # s, the outages that the palette and the key offer
MAV_ACTIONS = ("arm", "disarm", "offboard", "hold", "land")


class PaletteTarget(Protocol):
    """What the palette's entries call (the app, :class:`~gcs.dashboard.app.DashboardApp`)."""

    def send_mav(self, key: str, ids: list[int]) -> None: ...
    def confirm_group(self, what: str, ids: list[int], go: Callable[[], None]) -> None: ...
    def send_zenoh(self, cmd: Command) -> None: ...
    def selected_id(self) -> int | None: ...
    def all_ids(self) -> list[int]: ...
    def action_estop(self) -> None: ...
    def action_toggle_target(self) -> None: ...
    def palette_takeoff(self) -> None: ...


def palette_commands(app: PaletteTarget) -> Iterator[SystemCommand]:
    """The palette's entries: MAVLink commands per vehicle and for all, the emergency
    stop, and the Zenoh commands (method, outage, land-all, take-off)."""
    for key in MAV_ACTIONS:
        label = COMMANDS[key].label
        yield SystemCommand(
            f"{label.capitalize()}: selected vehicle",
            "COMMAND_LONG to the selected vehicle, waits for the ACK",
            lambda k=key: app.send_mav(k, [i for i in [app.selected_id()] if i]),
        )
        yield SystemCommand(
            f"{label.capitalize()}: all vehicles",
            "COMMAND_LONG to every vehicle, waits for each ACK",
            lambda k=key, what=label: app.confirm_group(
                what, app.all_ids(), lambda: app.send_mav(k, app.all_ids())),
        )
    yield SystemCommand(
        "Emergency stop (asks first)", "Flight termination of the target", app.action_estop
    )
    for m in METHODS:
        yield SystemCommand(
            f"Method {m}: all vehicles",
            "Switch collision avoidance at run time (Zenoh)",
            lambda m=m: app.send_zenoh(Command(kind="method", agent=0, method=m)),
        )
    for d in OUTAGES_S:
        yield SystemCommand(
            f"Outage {d:g} s: all vehicles",
            "Inject a communication outage (Zenoh)",
            lambda d=d: app.send_zenoh(Command(kind="outage", agent=0, duration_s=d)),
        )
    yield SystemCommand(
        "Coordinated land-all (Zenoh)",
        "Every agent lands on its own pad, lowest first, safety filter active",
        lambda: app.confirm_group("coordinated land-all", app.all_ids(), lambda: app.send_zenoh(
            Command(kind="land", agent=0, at_s=-1.0))),
    )
    yield SystemCommand(
        "Coordinated take-off: all vehicles",
        "OFFBOARD + arm every vehicle, then the ground start's layered climb (Zenoh)",
        app.palette_takeoff,
    )
    yield SystemCommand("Toggle command target (selected / all)", "", app.action_toggle_target)
