"""Progress of a mission run on stderr.

On a terminal: one bar redrawn in place (``\\r``), at most every ``redraw_s``. Anywhere
else (a log file, CI, a pipe): a plain line each time the run crosses another 10 % of its
duration, or ``every_s`` seconds after the previous line, so a 60 s mission adds about ten
lines to a log instead of a frame every 0.1 s::

    [rcbf]  30 %   18.0/60.0 s sim, 1.4x real time
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

BAR_WIDTH = 30


class Progress:
    """``update(t)`` with the mission time reached (s); ``close()`` at the end."""

    def __init__(
        self,
        duration: float,
        label: str = "",
        stream: TextIO | None = None,
        tty: bool | None = None,
        every_frac: float = 0.1,
        every_s: float = 10.0,
        redraw_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.duration = duration
        self.label = f"[{label}] " if label else ""
        self.stream = sys.stderr if stream is None else stream
        self.tty = self._isatty(self.stream) if tty is None else tty
        self.every_frac = every_frac
        self.every_s = every_s
        self.redraw_s = redraw_s
        self.clock = clock
        self.t0 = clock()
        self.t = 0.0
        self._last_write = -float("inf")
        self._last_step = -1  # index of the last every_frac step a plain line reported
        self._drawn = False

    @staticmethod
    def _isatty(stream: TextIO) -> bool:
        try:
            return stream.isatty()
        except (AttributeError, ValueError):  # no isatty, or a closed stream
            return False

    def fraction(self, t: float) -> float:
        return min(1.0, max(0.0, t / self.duration)) if self.duration > 0 else 1.0

    def _rate(self, now: float) -> float:
        wall = now - self.t0
        return self.t / wall if wall > 0 else 0.0

    def update(self, t: float, note: str = "") -> None:
        """The run reached mission time ``t`` (s); ``note`` is appended to the line."""
        self.t = t
        now = self.clock()
        frac = self.fraction(t)
        if self.tty:
            if now - self._last_write >= self.redraw_s or frac >= 1.0:
                self._draw(frac, now, note)
            return
        step = int(frac / self.every_frac + 1e-9)
        if step > self._last_step or now - self._last_write >= self.every_s:
            self._line(frac, now, note)
            self._last_step = step

    def close(self, note: str = "") -> None:
        """End the display: finish the bar's line, or write the last plain line if the
        run ended between two reports."""
        now = self.clock()
        frac = self.fraction(self.t)
        if self.tty:
            if self._drawn:
                self._draw(frac, now, note)
                self.stream.write("\n")
                self.stream.flush()
        elif int(frac / self.every_frac + 1e-9) > self._last_step or note:
            self._line(frac, now, note)

    def _text(self, now: float, note: str) -> str:
        tail = f"  {note}" if note else ""
        return (f"{self.t:6.2f}/{self.duration:.1f} s sim, {self._rate(now):5.1f}x real time"
                f"{tail}")

    def _draw(self, frac: float, now: float, note: str) -> None:
        full = int(BAR_WIDTH * frac)
        bar = "#" * full + "." * (BAR_WIDTH - full)
        self.stream.write(f"\r{self.label}[{bar}] {self._text(now, note)}")
        self.stream.flush()
        self._last_write = now
        self._drawn = True

    def _line(self, frac: float, now: float, note: str) -> None:
        self.stream.write(f"{self.label}{100 * frac:3.0f} % {self._text(now, note)}\n")
        self.stream.flush()
        self._last_write = now
