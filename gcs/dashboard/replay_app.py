"""``gcs dashboard --replay RUN``: the dashboard on a recorded run.

:class:`ReplayApp` is the live :class:`~gcs.dashboard.app.DashboardApp` (the same vehicle
rows, views, min-distance plot, event log and status line) fed by a
:class:`~gcs.dashboard.view.replay_source.ReplaySource` instead of MAVLink and Zenoh, with a
replay line (:class:`~gcs.dashboard.widgets.ReplayBar`) and these keys:

=====  ==================================================================
key    action
=====  ==================================================================
space  pause / play (from the start again at the end)
. ,    one frame forward / back (holds the replay)
+/-    faster / slower: x0.25, x0.5, x1, x2, x4, x8, x16
c      jump to the closest approach (the smallest min pair distance)
n p    jump to the next / previous event
t      target: the selected vehicle <-> all vehicles
q      quit
=====  ==================================================================

A jump holds the replay there (space plays on). Every command to the vehicles (arm, take
off, land, ...) is refused with one line in the event log: a record cannot be flown.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink
from textual.app import App, ComposeResult, SystemCommand
from textual.binding import Binding
from textual.screen import Screen

from gcs.formation.steer import FormationSteer

from .app import DashboardApp
from .px4modes import COMMANDS
from .view.replay_source import ReplaySource, load_run
from .widgets import EventLog, ReplayBar, StatusBar

REPLAY_POLL_S = 0.1  # s (wall) between two frames on screen
# the live dashboard's command keys -> what the refusal names
LIVE_ONLY = {
    "a": COMMANDS["arm"].label, "d": COMMANDS["disarm"].label,
    "f": COMMANDS["offboard"].label, "h": COMMANDS["hold"].label, "u": "take-off",
    "l": COMMANDS["land"].label, "x": "emergency stop", "m": "method", "o": "outage",
    "g": "go-to",
}  # fmt: skip


class ReplayClock:
    """What the app asks its commander for the mission line: the replay's time as the
    swarm's mission time; no link to command."""

    def __init__(self, source: ReplaySource) -> None:
        self.source = source

    def mission_time(self) -> float:
        return self.source.cursor.time

    def zenoh_up(self) -> bool:
        return False


class ReplayApp(DashboardApp, inherit_bindings=False):
    # the live keys' bindings are not inherited: the footer lists the replay's first, and
    # each command key of the live dashboard is refused (live_only)
    BINDINGS = [
        *App.BINDINGS,
        Binding("space", "pause", "Play"),
        Binding("full_stop", "step(1)", "Step"),
        Binding("comma", "step(-1)", "Back"),
        Binding("plus,equals_sign", "speed(1)", "Faster", key_display="+"),
        Binding("minus", "speed(-1)", "Slower"),
        Binding("c", "closest", "Closest"),
        Binding("n", "event(1)", "Next"),
        Binding("p", "event(-1)", "Prev"),
        Binding("t", "toggle_target", "One/All", show=False),
        Binding("q", "quit", "Quit"),
        *(Binding(k, f"live_only('{k}')", show=False) for k in LIVE_ONLY),
    ]

    def __init__(self, source: ReplaySource) -> None:
        sc = source.run.scenario
        steer = FormationSteer(sc) if sc.mission is not None else None
        super().__init__(source, ReplayClock(source), poll_s=REPLAY_POLL_S, steer=steer,
                         world=sc.world)
        self.replay = source

    def compose(self) -> ComposeResult:
        for w in super().compose():
            yield w
            if isinstance(w, StatusBar):
                yield ReplayBar(id="replay")

    def refresh_data(self) -> None:
        super().refresh_data()
        cur = self.replay.cursor
        # the state first: a narrow header cuts the run's name, not the time
        self.sub_title = f"replay {cur.state_text()} · {self.replay.run.name}"
        now = cur.min_dist_now
        for bar in self.query(ReplayBar):
            bar.show(cur.line_text(), now is not None and now < self.replay.d_safe)

    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        yield from App.get_system_commands(self, screen)  # Textual's own; none to the swarm

    # -- the replay's keys ------------------------------------------------------------
    def _moved(self, move: Callable[[], object]) -> object:
        """Run ``move`` on the cursor, then show its frame at once; a move back shows the
        event log again up to the new time."""
        before = self.replay.cursor.time
        out = move()
        if self.replay.cursor.time < before:
            log = self.query_one(EventLog)
            log.clear()
            log.lines_text.clear()
            self.replay.restart_events()
        self.refresh_data()
        return out

    def action_pause(self) -> None:
        self._moved(self.replay.cursor.toggle_pause)

    def action_step(self, frames: int) -> None:
        self._moved(lambda: self.replay.cursor.step(frames))

    def action_speed(self, steps: int) -> None:
        cur = self.replay.cursor
        self._moved(cur.faster if steps > 0 else cur.slower)

    def action_closest(self) -> None:
        if not self._moved(self.replay.cursor.to_closest):
            self.notify("no closest approach: the run has no min distance", timeout=3)

    def action_event(self, step: int) -> None:
        cur = self.replay.cursor
        if not self._moved(cur.next_event if step > 0 else cur.previous_event):
            self.notify(f"no {'next' if step > 0 else 'previous'} event", timeout=2)

    def action_live_only(self, key: str) -> None:
        what = LIVE_ONLY.get(key, key)
        self.log_event(0, "cmd", f"{what}: live only, refused in a replay (a recorded run "
                       "has no vehicles to command)", mavlink.MAV_SEVERITY_WARNING)


def build_replay(args: argparse.Namespace) -> tuple[ReplayApp, ReplaySource, None, str]:
    """(app, source, no launch, title) of ``gcs dashboard --replay RUN``; a RecordError or
    ValueError of one line when the run, its record or its scenario cannot be read."""
    clash = [f for f, on in (("--launch", args.launch), ("--demo", args.demo)) if on]
    if clash:
        raise ValueError(f"--replay plays a recorded run: not with {clash[0]}")
    try:
        run = load_run(Path(args.replay), args.scenario)
        source = ReplaySource(run)
    except ValueError as exc:  # RecordError too: one line whatever the scenario's message
        raise ValueError(" ".join(str(exc).split())) from None
    title = f"replay {run.name}"
    return ReplayApp(source), source, None, title

