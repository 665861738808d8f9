"""One line of a replay (``gcs dashboard --replay``): the min pair distance now and over
the run, the frame and the event (:meth:`gcs.dashboard.view.replay.ReplayCursor.line_text`)."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static


class ReplayBar(Static):
    DEFAULT_CSS = """
    ReplayBar { height: 1; background: $boost; padding: 0 1; }
    """

    def __init__(self, **kw) -> None:
        super().__init__("", **kw)
        self.text = ""

    def show(self, text: str, unsafe: bool = False) -> None:
        """Draw ``text``; ``unsafe``: the distance now is below D_safe (red)."""
        self.text = text
        self.update(Text(text, "bold red" if unsafe else "", no_wrap=True, overflow="ellipsis"))
