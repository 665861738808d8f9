"""The event log: STATUSTEXT, mode changes, failsafes, QP fallbacks, outages, ACKs.

Times are sim seconds, the header's clock (``-`` before the dashboard heard one); a repeated
event arrives here once with its count (:mod:`gcs.dashboard.view.timeline`)."""

from __future__ import annotations

import math

from rich.text import Text
from textual.widgets import RichLog

from ..view.state import DashEvent
from .fmt import SEVERITY_STYLE, SEVERITY_TAG


class EventLog(RichLog):
    DEFAULT_CSS = """
    EventLog { height: 1fr; }
    """

    def __init__(self, **kw) -> None:
        super().__init__(max_lines=1000, wrap=False, markup=False, auto_scroll=True, **kw)
        self.border_title = "Events"
        self.count = 0
        self.lines_text: list[str] = []  # plain copy, for tests

    def add(self, ev: DashEvent) -> None:
        line = Text(no_wrap=True)
        line.append(f"{ev.t:6.1f} " if math.isfinite(ev.t) else "     - ", "dim")  # sim s
        who = "GCS" if ev.agent == 0 else f"#{ev.agent}"
        line.append(f"{who:>3} ")
        sev = max(0, min(7, ev.severity))
        line.append(f"{SEVERITY_TAG[sev]:<5} ", SEVERITY_STYLE[sev] or "dim")
        line.append(ev.text, SEVERITY_STYLE[sev])
        self.write(line)
        self.count += 1
        self.lines_text.append(line.plain)
        del self.lines_text[:-1000]
