"""One line: swarm, links, command target, method, minimum distance, counters."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static

from ..view.state import SwarmView
from .fmt import num


class StatusBar(Static):
    DEFAULT_CSS = """
    StatusBar { height: 1; background: $boost; padding: 0 1; }
    """

    def show(self, view: SwarmView, target: str) -> None:
        t = Text(no_wrap=True, overflow="ellipsis")
        t.append(f"{view.swarm} ", "bold")
        t.append("tgt:", "dim")
        t.append(f"{target} ", "bold reverse")
        t.append(" mav:", "dim")
        t.append(view.link + " ")
        if view.signed:
            t.append("signed ", "green")
        t.append("zenoh:", "dim")
        zstyle = "green" if view.zenoh == "ok" else ("dim" if view.zenoh == "off" else "yellow")
        t.append(view.zenoh + " ", zstyle)
        t.append("method:", "dim")
        t.append(view.method + " ", "bold")
        t.append("dmin:", "dim")
        unsafe = view.min_dist is not None and view.min_dist < view.d_safe
        t.append(num(view.min_dist, 4, 2).strip() + " ", "bold red" if unsafe else "green")
        t.append("bad:", "dim")
        bad = view.bad_packets + view.bad_payloads
        t.append(f"{view.bad_packets}/{view.bad_payloads} ", "yellow" if bad else "")
        if view.rejected:
            t.append("rejected:", "dim")
            t.append(f"{view.rejected} ", "yellow")
        if view.collisions:
            t.append(f"COLLISIONS {view.collisions} ", "bold white on red")
        if view.sim_time is not None:
            t.append("sim:", "dim")
            t.append(f"{view.sim_time:.1f}s")
        self.update(t)
