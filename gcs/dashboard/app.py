"""The Textual dashboard: vehicle table, formation views, min-distance plot, event log.

The app draws whatever its *source* returns (``poll() -> (SwarmView, [DashEvent])``,
see :mod:`.state`) and sends commands through a *commander* (:mod:`.commands`).

Keys (also in the command palette, ctrl+p, for the selected vehicle or for all):

=====  =====================================================  =========================
key    action                                                 goes out as
=====  =====================================================  =========================
a      arm                                                    COMMAND_LONG 400 p1=1
d      disarm                                                 COMMAND_LONG 400 p1=0
f      start formation (OFFBOARD)                             DO_SET_MODE 176 129,6
h      hold (AUTO.LOITER)                                     DO_SET_MODE 176 129,4,3
u      take off, target ALL with Zenoh up: OFFBOARD + arm     DO_SET_MODE + COMMAND_LONG
       every vehicle, then (all ACKed) the coordinated        400, then Zenoh Command
       take-off of a ground start (docs/lifecycle.md)          "takeoff"
l      land; all vehicles with Zenoh up: coordinated land-all Zenoh Command "land" (else
       (docs/lifecycle.md), else per vehicle AUTO.LAND          NAV_LAND 21)
x      emergency stop (asks first)                            DO_FLIGHTTERMINATION 185
m      collision-avoidance method rcbf / apf / none           Zenoh Command "method"
o      inject a communication outage                          Zenoh Command "outage"
n      navigate: step, scale, turn, hold, resume the mission  Zenoh "mission" / "hold"
g      go to a typed centroid "x y z [yaw]" (ENU m, deg)      Zenoh Command "mission"
t      target: the selected vehicle <-> all vehicles
q      quit
=====  =====================================================  =========================

Every MAVLink command waits for its COMMAND_ACK; each result goes to the event log.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink
from textual.app import App, ComposeResult, SystemCommand
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.reactive import reactive
from textual.screen import Screen
from textual.widgets import Footer, Header

from gcs.formation.steer import FormationSteer
from swarm_common.wire import Command
from swarm_common.world.config import World

from . import group_commands as gc
from . import navigate as nav
from . import zenoh_commands as zc
from .group_commands import COMMAND_REPEAT_S, LAND_LEAD_S
from .mavlink_gcs import CommandResult
from .palette import OUTAGES_S, palette_commands
from .px4modes import COMMANDS
from .view.preflight import PlanEnvelope
from .view.state import DashEvent, SwarmView
from .widgets import (
    ChoiceScreen,
    ConfirmScreen,
    EventLog,
    FormationView,
    InputScreen,
    MinDistancePlot,
    MissionPanel,
    PreflightPanel,
    StatusBar,
    VehicleTable,
)
from .zenoh_feed import METHODS

log = logging.getLogger(__name__)

NOTICE = mavlink.MAV_SEVERITY_NOTICE
WARNING = mavlink.MAV_SEVERITY_WARNING
ERROR = mavlink.MAV_SEVERITY_ERROR
WIDE_TABLE_COLUMNS = 150
FORMATION_TICK_S = 0.05  # s between two ticks of the formation vehicle (formation_link)


class DashboardApp(App[int]):
    CSS_PATH = Path(__file__).with_name("dashboard.tcss")
    TITLE = "swarm GCS"
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (120, "-wide")]
    VERTICAL_BREAKPOINTS = [(0, "-short"), (40, "-tall")]
    BINDINGS = [
        Binding("a", "mav('arm')", "Arm"),
        Binding("d", "mav('disarm')", "Disarm"),
        Binding("f", "mav('offboard')", "Formation"),
        Binding("h", "mav('hold')", "Hold"),
        Binding("u", "takeoff", "Take off"),
        Binding("l", "land", "Land"),
        Binding("x", "estop", "E-STOP"),
        Binding("m", "method", "Method"),
        Binding("o", "outage", "Outage"),
        Binding("n", "navigate", "Navigate"),
        Binding("g", "goto", "Go to"),
        Binding("t", "toggle_target", "One/All"),
        Binding("q", "quit", "Quit"),
    ]

    target_all: reactive[bool] = reactive(False)

    def __init__(
        self,
        source: Any,
        commander: Any = None,
        poll_s: float = 0.25,
        title: str | None = None,
        steer: FormationSteer | None = None,
        world: World | None = None,
        formation: Any = None,
        preflight: PlanEnvelope | None = None,
    ) -> None:
        super().__init__()
        self.preflight = preflight  # the plan's envelope, shown until take-off
        self.world = world  # the scenario's obstacles and geofence, drawn in both views
        self.formation = formation  # gcs.dashboard.formation_link, ticked on this loop
        self.steer = steer  # a mission scenario's formation steering (n), else None
        self.source = source
        self.commander = commander
        self.poll_s = poll_s
        self.command_repeat_s = COMMAND_REPEAT_S  # s between the copies of a command
        self.view: SwarmView | None = None
        self.results: list[CommandResult] = []
        self.published: list[str] = []
        if title:
            self.sub_title = title

    # -- layout --------------------------------------------------------------------
    def compose(self) -> ComposeResult:
        yield Header()
        yield StatusBar(id="status")
        yield PreflightPanel(self.preflight, id="preflight")
        yield MissionPanel(id="mission", shown=self.steer is not None)
        yield VehicleTable(id="vehicles")
        with Horizontal(id="bottom"):
            with Horizontal(id="views"):
                yield FormationView("xy", self.world, id="top")
                yield FormationView("xz", self.world, id="side-view")
            with Vertical(id="side"):
                yield MinDistancePlot(id="dmin")
                yield EventLog(id="events")
        yield Footer()

    def on_mount(self) -> None:
        self.refresh_data()
        self.query_one(VehicleTable).focus()
        if getattr(self.source, "live", True):
            self.set_interval(self.poll_s, self.refresh_data)
        if self.formation is not None:
            self.set_interval(FORMATION_TICK_S, self.formation.tick)

    def on_resize(self) -> None:
        if self.view is not None:
            self._draw(self.view)

    # -- data ----------------------------------------------------------------------
    def refresh_data(self) -> None:
        try:
            view, events = self.source.poll()
        except Exception as exc:  # any feed hiccup: logged, the ground station stays up
            log.warning("dashboard source poll failed", exc_info=True)
            self.log_event(0, "error", f"source: {exc!r}", ERROR)
            return
        self.view = view
        try:
            for ev in events:
                self.query_one(EventLog).add(ev)
            self._draw(view)
        except NoMatches:  # a last timer tick while the app shuts down: the widgets are gone
            log.debug("dashboard refresh after its widgets were removed")

    def _draw(self, view: SwarmView) -> None:
        compact = self.size.width < WIDE_TABLE_COLUMNS
        self.query_one(VehicleTable).show(view, compact)
        for fv in self.query(FormationView):
            fv.show(view)
        self.query_one(MinDistancePlot).show(view)
        self.query_one(StatusBar).show(view, self.target_label())
        self.query_one(PreflightPanel).show(view.params, view.flying)
        if (p := nav.progress(self.steer, self.commander)) is not None:  # the mission, its path
            self.query_one(MissionPanel).show(p)
            self.query_one("#top", FormationView).show_path(p.path, p.next_centroid)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        return action != "goto" or self.steer is not None  # g: for a mission scenario only

    def watch_target_all(self) -> None:
        if self.view is not None:
            self.query_one(StatusBar).show(self.view, self.target_label())

    def log_event(
        self, agent: int, kind: str, text: str, severity: int = mavlink.MAV_SEVERITY_INFO
    ) -> None:
        t = self.view.t if self.view is not None else math.nan  # sim s, as every line
        self.query_one(EventLog).add(DashEvent(t, agent, kind, text, severity))

    # -- targets -------------------------------------------------------------------
    def all_ids(self) -> list[int]:
        return [r.id for r in self.view.rows] if self.view is not None else []

    def selected_id(self) -> int | None:
        return self.query_one(VehicleTable).selected_id

    def targets(self) -> list[int]:
        if self.target_all:
            return self.all_ids()
        sel = self.selected_id()
        return [] if sel is None else [sel]

    def target_label(self, ids: list[int] | None = None) -> str:
        if ids is None:
            if self.target_all:
                return "ALL"
            sel = self.selected_id()
            return "-" if sel is None else f"#{sel}"
        if len(ids) > 1 and ids == self.all_ids():
            return "ALL"
        return ",".join(f"#{i}" for i in ids) or "-"

    # -- actions -------------------------------------------------------------------
    def action_toggle_target(self) -> None:
        self.target_all = not self.target_all
        self.notify(f"command target: {self.target_label()}", timeout=2)

    def confirm_group(self, what: str, ids: list[int], go: Callable[[], None]) -> None:
        """A command for more than one vehicle runs once the operator confirmed the list of
        its targets (``y``); one vehicle: at once."""
        if len(ids) <= 1:
            go()
            return

        def done(yes: bool | None) -> None:
            if yes:
                go()
            else:
                self.log_event(0, "cmd", f"{what} -> {self.target_label(ids)} cancelled")

        self.push_screen(ConfirmScreen(gc.group_question(what, ids)), done)

    def action_mav(self, key: str) -> None:
        ids = self.targets()
        self.confirm_group(COMMANDS[key].label, ids, lambda: self.send_mav(key, ids))

    def send_mav(self, key: str, ids: list[int]) -> None:
        spec = COMMANDS[key]
        if not ids:
            self.log_event(0, "cmd", f"{spec.label}: no vehicle selected", WARNING)
            return
        if self.commander is None:
            self.log_event(0, "cmd", f"{spec.label}: read-only (no command link)", WARNING)
            return
        self.log_event(0, "cmd", f"{spec.label} -> {self.target_label(ids)}", NOTICE)
        self.run_worker(self._mav_worker(key, ids), group="mav", exit_on_error=False)

    async def _mav_worker(self, key: str, ids: list[int]) -> None:
        self.log_results(await asyncio.gather(*(self.commander.mav(i, key) for i in ids)))

    def log_results(self, results: Iterable[CommandResult]) -> None:
        for r in results:
            self.results.append(r)
            self.log_event(
                r.sysid, "ack", r.describe(), mavlink.MAV_SEVERITY_INFO if r.ok else ERROR
            )

    def action_land(self) -> None:
        """All vehicles with a Zenoh link up: the coordinated land-all (offboard.agent.landing),
        starting LAND_LEAD_S after the swarm's latest mission time, safety filter active;
        otherwise MAV_CMD_NAV_LAND (AUTO.LAND) to each target, as before."""
        ids = self.targets()
        up = getattr(self.commander, "zenoh_up", None)
        if self.target_all and len(ids) > 1 and callable(up) and up():

            def land_all() -> None:  # the common t_L from the mission time once confirmed
                at_s = gc.mission_time_plus(self.commander, LAND_LEAD_S)
                self.send_zenoh(Command(kind="land", agent=0, at_s=at_s))

            self.confirm_group("coordinated land-all", ids, land_all)
            return
        self.confirm_group(COMMANDS["land"].label, ids, lambda: self.send_mav("land", ids))

    def action_takeoff(self) -> None:
        """Target ALL with a Zenoh link up: OFFBOARD then arm every vehicle, and once every
        one ACKed, the coordinated take-off (offboard.agent.takeoff) at the swarm's latest
        mission time + TAKEOFF_LEAD_S; the daemons of a ground start held on the pads
        climb from then on (an airborne start ignores it: this is then ``f`` + ``a``)."""
        ids = self.targets()
        up = getattr(self.commander, "zenoh_up", None)
        why = ""
        if self.commander is None:
            why = "read-only (no command link)"
        elif not (callable(up) and up()):
            why = "needs Zenoh (started with --no-zenoh?)"
        elif not (self.target_all and len(ids) > 1):
            why = "needs target ALL (t)"
        if why:
            self.log_event(0, "cmd", f"take-off is for all vehicles at once: {why}", WARNING)
            return

        def go() -> None:
            self.log_event(0, "cmd", "take-off -> ALL: OFFBOARD, arm, then take-off", NOTICE)
            self.run_worker(gc.takeoff_sequence(self, ids), group="mav", exit_on_error=False)

        self.confirm_group("take-off (OFFBOARD, arm, climb)", ids, go)

    def action_estop(self) -> None:
        ids = self.targets()
        if not ids:
            self.log_event(0, "cmd", "emergency stop: no vehicle selected", WARNING)
            return
        label = self.target_label(ids)

        def done(yes: bool | None) -> None:
            if yes:
                self.send_mav("terminate", ids)
            else:
                self.log_event(0, "cmd", f"emergency stop {label} cancelled")

        self.push_screen(
            ConfirmScreen(f"EMERGENCY STOP {label} ({gc.id_list(ids)})?\n"
                          "Flight termination: motors stop at once."),
            done,
        )

    def action_method(self) -> None:
        ids = self.targets()
        agent = 0 if self.target_all or not ids else ids[0]
        who = "all" if agent == 0 else f"#{agent}"

        def done(choice: str | None) -> None:
            if choice:
                self.send_zenoh(Command(kind="method", agent=agent, method=choice))

        self.push_screen(
            ChoiceScreen(f"Collision avoidance for {who}:", [(m, m) for m in METHODS]),
            done,
        )

    def action_navigate(self) -> None:
        """The navigation menu (gcs.dashboard.navigate): a step, scale or turn of the whole
        formation, hold or resume; needs a launched scenario with a [mission] and Zenoh."""
        self._steer("navigation", ChoiceScreen(nav.MENU_TITLE, nav.CHOICES), nav.command_for)

    def action_goto(self) -> None:
        """g: fly the formation to a typed centroid (navigate.goto_command)."""
        self._steer("go-to", InputScreen(nav.GOTO_PROMPT, nav.GOTO_HINT), nav.goto_command)

    def _steer(self, what: str, ask: Screen[str | None], make: nav.MakeCommand) -> None:
        """Ask (``ask``), then send ``make(steer, answer, t)`` (navigate.sender)."""
        t_now = nav.steer_time(self.steer, self.commander)
        if self.steer is None or t_now is None:
            self.log_event(0, "cmd", f"{what} {nav.NEEDS}", WARNING)
            return
        self.push_screen(ask, nav.sender(self, what, self.steer, t_now, make))

    def action_outage(self) -> None:
        ids = self.targets()
        agent = 0 if self.target_all or not ids else ids[0]
        who = "all" if agent == 0 else f"#{agent}"

        def done(choice: str | None) -> None:
            if choice:
                self.send_zenoh(Command(kind="outage", agent=agent, duration_s=float(choice)))

        self.push_screen(
            ChoiceScreen(
                f"Inject a communication outage on {who}:",
                [(f"{d:g}", f"{d:g} s") for d in OUTAGES_S],
            ),
            done,
        )

    def send_zenoh(self, cmd: Command) -> None:
        """Publish ``cmd`` (:func:`.zenoh_commands.publish`); a take-off or land-all is
        published again COMMAND_REPEATS times (:func:`.group_commands.repeat_command`)."""
        if zc.publish(self, cmd) and cmd.kind in ("land", "takeoff"):
            self.run_worker(gc.repeat_command(self, cmd), group="repeat", exit_on_error=False)

    def palette_takeoff(self) -> None:
        self.target_all = True
        self.action_takeoff()

    # -- command palette ---------------------------------------------------------------
    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        yield from super().get_system_commands(screen)
        yield from palette_commands(self)
