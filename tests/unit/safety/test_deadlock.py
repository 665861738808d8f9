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


class _DequeDetector:
    """The detector as it was written before its window became a compiled ring: the
    reference the ring must agree with, step for step."""

    def __init__(self, cfg: DeadlockConfig) -> None:
        from collections import deque

        self.cfg = cfg
        self.hist: deque[tuple[float, float, bool, np.ndarray | None]] = deque()
        self.held = 0
        self.low = 0

    def update_held(self, t: float, err_m: float, held: bool, pos: np.ndarray | None) -> bool:
        cfg = self.cfg
        self.hist.append((t, err_m, held, None if pos is None else np.array(pos, float)))
        self.held += held
        self.low += err_m <= cfg.err_tol_m
        while len(self.hist) > 1 and self.hist[1][0] <= t - cfg.window_s:
            _, e_old, held_old, _ = self.hist.popleft()
            self.held -= held_old
            self.low -= e_old <= cfg.err_tol_m
        t0, e0, _, p0 = self.hist[0]
        return bool(
            t - t0 >= cfg.window_s and self.low == 0 and e0 - err_m < cfg.min_progress * e0
            and self.held >= cfg.held_fraction * len(self.hist)
            and (p0 is None or pos is None
                 or float(np.linalg.norm(np.asarray(pos, float) - p0)) < cfg.max_travel_m)
        )


@pytest.mark.parametrize("seed", range(6))
def test_the_ring_agrees_with_the_deque_step_for_step(seed: int) -> None:
    """Random runs: irregular steps (missed periods), stalls, falls, NaN errors, errors
    within the tolerance, held and free steps, positions given or not, creeping and
    travelling agents, and windows long enough that the ring grows past its capacity."""
    rng = np.random.default_rng(seed)
    window = [3.0, 6.0, 25.0][seed % 3]  # 25 s at 50 Hz: 1,251 samples, the ring grows
    cfg = DeadlockConfig(window_s=window)
    ring, ref = DeadlockDetector(cfg), _DequeDetector(cfg)
    t, err, p = 0.0, 0.8, np.zeros(3)
    flagged = 0
    phase = int(1.6 * window / DT)  # each kind of motion lasts longer than a window
    for k in range(5 * phase):
        t += DT * (1 + (rng.random() < 0.05) * int(rng.integers(1, 4)))
        mode = (k // phase) % 4  # stall, fall, creep near the tolerance, travel
        err = {0: err, 1: err * 0.995, 2: 0.1 + 0.001 * rng.standard_normal(),
               3: err}[mode]
        if rng.random() < 0.01:
            err = float("nan")
        elif not np.isfinite(err) or err < 0.05:
            err = 0.8
        p = p + (rng.normal(0.0, 0.01, 3) if mode != 3 else np.array([0.01, 0.0, 0.0]))
        held = bool(rng.random() < 0.8)
        pos = None if seed % 2 and rng.random() < 0.3 else p.copy()
        got = ring.update_held(t, float(err), held, pos)
        assert got == ref.update_held(t, float(err), held, pos), (seed, k)
        flagged += got
    assert flagged > 0  # the runs reach the deadlock, not only its absence


@pytest.mark.parametrize("seed", range(3))
def test_the_tracking_step_is_the_held_step_of_its_error(seed: int) -> None:
    """update_tracking (the follower's call: the error ‖p − ξ_p‖ and the travel test on p,
    in the compiled step) against update_held given that error (numpy's norm, 1e-12 apart
    at most) and p: the same answers step for step, stalls and travel included."""
    rng = np.random.default_rng(100 + seed)
    cfg = DeadlockConfig(window_s=3.0)
    a, b = DeadlockDetector(cfg), DeadlockDetector(cfg)
    p, target = rng.normal(0.0, 2.0, 3), np.zeros(12)
    flagged = 0
    for k in range(1500):
        mode = (k // 300) % 3  # stalled 0.8 m away, closing in, travelling away
        if mode == 1:
            p = p + (target[0:3] - p) * 0.02
        elif mode == 2:
            p = p + np.array([0.02, 0.0, 0.0])
        p = p + rng.normal(0.0, 1e-4, 3)
        if k % 300 == 0:
            target[0:3] = p + rng.normal(0.0, 0.5, 3)
        held = bool(rng.random() < 0.9)
        got = a.update_tracking(k * DT, p.copy(), target.copy(), held)
        want = b.update_held(k * DT, float(np.linalg.norm(p - target[0:3])), held, p.copy())
        assert got == want, (seed, k)
        flagged += got
    assert flagged > 0  # the runs reach a deadlock, not only its absence
