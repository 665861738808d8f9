"""gcs.mission.progress.Progress: a redrawn bar on a terminal, occasional plain lines elsewhere."""

from __future__ import annotations

import io

from gcs.mission.progress import Progress


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def drive(p: Progress, clock: FakeClock, duration: float, wall_per_sim: float) -> None:
    """Report every 0.02 s of mission time, ``wall_per_sim`` wall seconds per sim second."""
    steps = int(round(duration / 0.02))
    for k in range(steps + 1):
        clock.now = k * 0.02 * wall_per_sim
        p.update(k * 0.02)
    p.close()


def test_not_a_tty_writes_a_line_per_ten_percent() -> None:
    out, clock = io.StringIO(), FakeClock()
    p = Progress(60.0, label="rcbf", stream=out, clock=clock)
    assert not p.tty  # StringIO is not a terminal
    drive(p, clock, 60.0, wall_per_sim=0.5)
    text = out.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert len(lines) == 11, lines  # 0 %, 10 %, ..., 100 %: not 3000 frames
    assert lines[0].startswith("[rcbf]   0 %") and lines[-1].startswith("[rcbf] 100 %")
    assert "60.00/60.0 s sim" in lines[-1] and "2.0x real time" in lines[-1]


def test_not_a_tty_slow_run_also_reports_every_ten_seconds() -> None:
    out, clock = io.StringIO(), FakeClock()
    p = Progress(10.0, stream=out, clock=clock, tty=False)
    drive(p, clock, 10.0, wall_per_sim=10.0)  # 1 s of mission per 10 s of wall clock: 100 s
    lines = out.getvalue().splitlines()
    assert 11 <= len(lines) <= 21, lines  # deciles, plus at most one line per 10 s between


def test_close_reports_where_a_cut_short_run_stopped() -> None:
    out, clock = io.StringIO(), FakeClock()
    p = Progress(10.0, stream=out, clock=clock, tty=False)
    p.update(0.0)
    clock.now = 1.0
    p.update(2.5)  # 25 %: reported as the 20 % decile
    p.update(2.9)
    p.close("stopped")
    lines = out.getvalue().splitlines()
    assert len(lines) == 3 and lines[-1].startswith(" 29 %") and lines[-1].endswith("stopped")


def test_tty_redraws_in_place_at_most_every_redraw_interval() -> None:
    out, clock = io.StringIO(), FakeClock()
    p = Progress(10.0, stream=out, clock=clock, tty=True, redraw_s=0.1)
    drive(p, clock, 10.0, wall_per_sim=0.1)  # 1 s of wall clock in all
    text = out.getvalue()
    frames = text.count("\r")
    assert 5 <= frames <= 13, frames  # ~every 0.1 s plus the final frames, not 500
    assert text.endswith("\n") and text.count("\n") == 1
    assert "[" + "#" * 30 + "]" in text
