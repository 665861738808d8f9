"""Minimum inter-agent distance over time, with the D_safe line (block-character plot)."""

from __future__ import annotations

from rich.text import Text
from textual.widget import Widget

from ..view.state import SwarmView

BLOCKS = " ▁▂▃▄▅▆▇█"


class MinDistancePlot(Widget):
    DEFAULT_CSS = """
    MinDistancePlot { border: round $primary 60%; height: 7; }
    """

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.view: SwarmView | None = None
        self.border_title = "min distance"

    def show(self, view: SwarmView) -> None:
        self.view = view
        cur = "-" if view.min_dist is None else f"{view.min_dist:.2f} m"
        self.border_title = f"min dist {cur}"
        self.border_subtitle = f"D_safe {view.d_safe:.2f} m"
        self.refresh()

    def render(self) -> Text:
        w, h = self.content_size.width, self.content_size.height
        if self.view is None or w < 8 or h < 1:
            return Text("")
        v = self.view
        gut = 5
        width = w - gut
        vals = v.min_dist_history[-width:]
        top = max([*vals, 2 * v.d_safe, 0.1]) * 1.1
        safe_row = h - 1 - min(h - 1, int(v.d_safe / top * h))
        text = Text(no_wrap=True)
        for r in range(h):
            if r == 0:
                label = f"{top:4.1f} "
            elif r == safe_row:
                label = f"{v.d_safe:4.2f} "[-5:]
            elif r == h - 1:
                label = "   0 "
            else:
                label = "     "
            text.append(label[:gut], "dim" if r != safe_row else "red")
            from_bottom = h - 1 - r
            pad = width - len(vals)
            for c in range(width):
                if c < pad:
                    ch, st = " ", ""
                else:
                    x = vals[c - pad]
                    eighths = int(round(x / top * h * 8))
                    fill = max(0, min(8, eighths - from_bottom * 8))
                    ch = BLOCKS[fill]
                    st = "red" if x < v.d_safe else "green"
                if r == safe_row and ch == " ":
                    ch, st = "─", "red"
                text.append(ch, st or None)
            if r < h - 1:
                text.append("\n")
        return text
