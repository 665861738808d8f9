"""The replay's clock over a recorded run (``gcs dashboard --replay``): plain numbers, no
Textual, no files.

:class:`ReplayCursor` holds the replay time (s, on the run's sim clock) and maps it to a
frame: the last sample of the series at or before it. It moves on with the wall clock times
a speed of :data:`SPEEDS` while it plays, steps one frame, and jumps to the closest approach
(the step of the smallest ``min_dist``, the value ``metrics.json`` reports as
``min_distance_m``) and to each event's time. A jump or a step holds the replay there
(paused); it stops at the end of the run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)  # × sim time per wall second, the + / - ladder
HISTORY_PERIOD_S = 0.25  # s per bar of the min-distance plot (the live dashboard's 4 Hz)
HISTORY_LEN = 600  # bars kept, as the live source
TIME_TOL_S = 1e-9  # s: an event stamped in whole ns falls on its step's sample


def fmt_dist(x: float | None) -> str:
    """A distance as the replay line shows it (m, 3 decimals; ``-`` unknown)."""
    return "-" if x is None or not math.isfinite(x) else f"{x:.3f} m"


def speed_label(speed: float) -> str:
    """``x0.25``, ``x1``, ``x16``."""
    return f"x{speed:g}"


def series_problem(t: np.ndarray, min_dist: np.ndarray) -> str | None:
    """Why sample times ``t`` and ``min_dist`` cannot be replayed, or None."""
    t, md = np.asarray(t), np.asarray(min_dist)
    if t.ndim != 1 or len(t) == 0 or not np.all(np.isfinite(t)):
        return "the series has no steps, or a sample time that is not a number"
    if np.any(np.diff(t) <= 0):
        return "the series' sample times do not increase"
    if md.shape != t.shape:
        return f"min_dist has shape {md.shape}, not {t.shape}"
    return None


class ReplayCursor:
    """Replay time over the sample times ``t`` (K,) of a series, its ``min_dist`` (K,) and
    the ``event_times`` (s, clamped to the run). ``ValueError`` when :func:`series_problem`
    finds one."""

    def __init__(self, t: np.ndarray, min_dist: np.ndarray,
                 event_times: Sequence[float] = ()) -> None:
        if (why := series_problem(t, min_dist)) is not None:
            raise ValueError(why)
        t = np.asarray(t, float)
        md = np.asarray(min_dist, float)
        self.t, self.min_dist = t, md
        self.t0, self.t1 = float(t[0]), float(t[-1])
        self.events = sorted(min(max(float(e), self.t0), self.t1) for e in event_times
                             if math.isfinite(e))
        self.time = self.t0
        self.paused = False
        self.speed_index = SPEEDS.index(1.0)
        finite = np.isfinite(md)
        self.closest: int | None = int(np.nanargmin(md)) if finite.any() else None
        self.run_min: float | None = None if self.closest is None else float(md[self.closest])
        # the plot's bars: the frames where each HISTORY_PERIOD_S bin of the run starts
        bins = self.t0 + HISTORY_PERIOD_S * np.arange(
            int((self.t1 - self.t0) / HISTORY_PERIOD_S + TIME_TOL_S) + 1)
        starts = np.unique(np.searchsorted(t, bins - TIME_TOL_S))
        self._bin_starts = starts[starts < len(t)]

    # -- where the cursor is ----------------------------------------------------------
    @property
    def speed(self) -> float:
        return SPEEDS[self.speed_index]

    @property
    def at_end(self) -> bool:
        return self.time >= self.t1

    def frame_at(self, time: float) -> int:
        """The last sample at or before ``time`` (clamped to the run)."""
        k = int(np.searchsorted(self.t, time + TIME_TOL_S, side="right")) - 1
        return min(max(k, 0), len(self.t) - 1)

    @property
    def frame(self) -> int:
        return self.frame_at(self.time)

    @property
    def min_dist_now(self) -> float | None:
        """The series' min pair distance at the current frame (m; None when unknown)."""
        x = float(self.min_dist[self.frame])
        return x if math.isfinite(x) else None

    def event_index(self) -> int:
        """How many events are at or before the replay time."""
        return int(np.searchsorted(self.events, self.time + TIME_TOL_S, side="right"))

    def history(self) -> list[float]:
        """The min-distance plot up to now: the smallest ``min_dist`` of each
        :data:`HISTORY_PERIOD_S` bin so far (the last bin up to the current frame)."""
        k = self.frame
        starts = self._bin_starts[self._bin_starts <= k]
        vals = np.fmin.reduceat(self.min_dist[: k + 1], starts)
        return [float(x) for x in vals[-HISTORY_LEN:] if math.isfinite(x)]

    # -- moving it ----------------------------------------------------------------------
    def advance(self, wall_s: float) -> None:
        """``wall_s`` seconds of wall time went by: playing, move on ``wall_s × speed``; at
        the end of the run, stop there (paused)."""
        if self.paused or not (wall_s > 0):
            return
        self.time = min(self.time + wall_s * self.speed, self.t1)
        if self.at_end:
            self.paused = True

    def seek(self, time: float, pause: bool = True) -> None:
        """Go to ``time`` (clamped to the run), held there when ``pause``."""
        self.time = min(max(float(time), self.t0), self.t1)
        if pause:
            self.paused = True

    def toggle_pause(self) -> None:
        """Pause, or play on (from the start again once at the end)."""
        if self.paused and self.at_end:
            self.time = self.t0
        self.paused = not self.paused

    def step(self, frames: int) -> None:
        """Hold the replay and move ``frames`` samples (clamped to the run)."""
        k = min(max(self.frame + frames, 0), len(self.t) - 1)
        self.seek(float(self.t[k]))

    def faster(self) -> None:
        self.speed_index = min(self.speed_index + 1, len(SPEEDS) - 1)

    def slower(self) -> None:
        self.speed_index = max(self.speed_index - 1, 0)

    def to_closest(self) -> bool:
        """Hold at the closest approach; False when the series has no finite distance."""
        if self.closest is None:
            return False
        self.seek(float(self.t[self.closest]))
        return True

    def next_event(self) -> bool:
        """Hold at the first event after the replay time; False when there is none."""
        later = [e for e in self.events if e > self.time + TIME_TOL_S]
        if not later:
            return False
        self.seek(later[0])
        return True

    def previous_event(self) -> bool:
        """Hold at the last event before the replay time; False when there is none."""
        earlier = [e for e in self.events if e < self.time - TIME_TOL_S]
        if not earlier:
            return False
        self.seek(earlier[-1])
        return True

    # -- what the header and the replay line say ------------------------------------------
    def state_text(self) -> str:
        """The header's part: replay time, speed and state, e.g. ``1.24/2.98 s · x1 ·
        paused``."""
        state = "end" if self.paused and self.at_end else ("paused" if self.paused
                                                            else "playing")
        return f"{self.time:.2f}/{self.t1:.2f} s · {speed_label(self.speed)} · {state}"

    def line_text(self) -> str:
        """The replay line: the min distance now and over the run, the frame and event."""
        at = "" if self.closest is None else f" at {self.t[self.closest]:.2f} s"
        return (f"dmin {fmt_dist(self.min_dist_now)} · run min {fmt_dist(self.run_min)}{at}"
                f" · frame {self.frame + 1}/{len(self.t)}"
                f" · event {self.event_index()}/{len(self.events)}")
