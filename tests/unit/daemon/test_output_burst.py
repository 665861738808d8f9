"""offboard.daemon.output_burst.OutputBurst: held sends go out only on flush, in order."""

from __future__ import annotations

from offboard.daemon.output_burst import OutputBurst


def test_burst_keeps_order_and_sends_only_on_flush() -> None:
    got: list[int] = []
    burst = OutputBurst()
    for i in range(5):
        burst.hold(got.append, i)
    assert got == [] and len(burst) == 5
    assert burst.flush() == 5 and got == [0, 1, 2, 3, 4] and len(burst) == 0
    assert burst.flush() == 0 and got == [0, 1, 2, 3, 4]
