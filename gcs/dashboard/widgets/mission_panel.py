"""One line: where the formation's mission stands (:mod:`..mission_progress`): the next
waypoint, its centroid (ENU, m), the time to arrive there and the share of the plan done;
``holding`` or ``finished``; ``no mission`` without one."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static

from ..view.mission_progress import MissionProgress

NO_MISSION = "no mission"
WAITING = "mission: waiting for the swarm's mission time (Zenoh)"


class MissionPanel(Static):
    DEFAULT_CSS = """
    MissionPanel { height: 1; background: $boost; padding: 0 1; }
    """

    def __init__(self, shown: bool = True, **kw) -> None:
        self.text = WAITING if shown else NO_MISSION
        super().__init__(Text(self.text, "dim"), **kw)
        self.display = shown  # hidden: the app has no mission
        self.progress: MissionProgress | None = None

    def show(self, progress: MissionProgress | None, has_mission: bool = True) -> None:
        """Draw ``progress``; None: :data:`WAITING` (``has_mission``) or :data:`NO_MISSION`."""
        self.progress = progress
        if progress is None:
            self.text = WAITING if has_mission else NO_MISSION
            self.update(Text(self.text, "dim"))
            return
        self.text = progress.line()
        if progress.holding:
            style = "bold yellow"
        elif progress.finished:
            style = "green"
        else:
            style = ""
        t = Text(no_wrap=True, overflow="ellipsis")
        t.append("mission ", "dim")
        t.append(self.text, style)
        self.update(t)
