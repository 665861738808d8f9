"""The deadlock detector (offboard.safety.deadlock)."""

from __future__ import annotations

import numpy as np
import pytest

from offboard.safety.deadlock import DeadlockConfig, DeadlockDetector

DT = 0.02  # s, 50 Hz


def _feed(det: DeadlockDetector, errs: list[float], corr: float, t0: float = 0.0) -> list[bool]:
    return [det.update(t0 + k * DT, e, corr) for k, e in enumerate(errs)]


def test_a_stalled_error_held_by_the_filter_is_flagged_after_the_window() -> None:
    det = DeadlockDetector(DeadlockConfig(window_s=3.0))
    out = _feed(det, [0.5] * 200, corr=1.0)  # 4 s
    first = out.index(True)
    assert first * DT == pytest.approx(3.0, abs=DT + 1e-9)
    assert all(out[first:])


def test_a_falling_error_is_not_a_deadlock() -> None:
    """1.0 → 0.2 m over 4 s (20 % of the error per second) with the filter active."""
    det = DeadlockDetector()
    errs = [1.0 - 0.8 * k / 199 for k in range(200)]
    assert not any(_feed(det, errs, corr=1.0))


def test_a_stall_without_the_filter_is_not_a_deadlock() -> None:
    det = DeadlockDetector()
    assert not any(_feed(det, [0.5] * 200, corr=0.0))


def test_a_stall_inside_the_tolerance_is_formed_not_deadlocked() -> None:
    det = DeadlockDetector()
    assert not any(_feed(det, [0.05] * 200, corr=1.0))


def test_the_flag_clears_when_the_error_falls_again() -> None:
    det = DeadlockDetector()
    assert _feed(det, [0.5] * 200, corr=1.0)[-1]
    # then the pair gives way: the error falls 0.5 → 0.05 m in 1 s
    out = _feed(det, [0.5 - 0.45 * k / 49 for k in range(50)], corr=1.0, t0=200 * DT)
    assert not out[-1]


def test_reset_forgets_the_window() -> None:
    det = DeadlockDetector()
    _feed(det, [0.5] * 200, corr=1.0)
    det.reset()
    assert not det.active
    assert not any(_feed(det, [0.5] * 100, corr=1.0, t0=10.0))  # 2 s < window


def test_bad_configuration_is_refused() -> None:
    with pytest.raises(ValueError):
        DeadlockConfig(window_s=0.0)
    with pytest.raises(ValueError):
        DeadlockConfig(min_progress=1.0)


def test_a_stalled_error_while_the_agent_travels_is_not_a_deadlock() -> None:
    """Winding around an obstacle: the error stays at 0.5 m for 5 s under the filter while
    the agent moves 0.25 m/s (0.75 m per 3 s window, over max_travel_m = 0.5 m);
    the same stall standing still (or creeping at 0.05 m/s) is flagged."""
    for speed, flagged in ((0.25, False), (0.05, True), (0.0, True)):
        det = DeadlockDetector(DeadlockConfig(window_s=3.0))
        out = [det.update_held(k * DT, 0.5, True, np.array([speed * k * DT, 0.0, 5.0]))
               for k in range(250)]
        assert any(out) is flagged, speed
