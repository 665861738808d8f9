"""offboard.daemon.nav_check and the runner-loss hold it starts: a follower whose estimate left its
vehicle's odometry is held on odometry and landed, and truth coming back does not give it
back to the estimate."""

from __future__ import annotations

import numpy as np
import pytest

from offboard.agent.follower import MAX_COAST_PERIODS
from offboard.daemon.nav_check import NAV_GATE_M, NAV_GATE_STEPS, NAV_GRACE_S, NavigationCheck
from offboard.daemon.runner_loss import RunnerLoss

P = np.array([1.0, 2.0, 3.0])
HZ = 50
GRACE = int(NAV_GRACE_S * HZ)


def _past_grace(nav: NavigationCheck) -> int:
    """Steps the check through its start-up grace (in agreement); the next step."""
    for k in range(GRACE):
        assert not nav.update(k, P + 50.0, P)  # a start-up error: not counted
    return GRACE


def test_latches_after_consecutive_disagreements_only() -> None:
    nav = NavigationCheck(HZ)
    k = _past_grace(nav)
    off = P + np.array([0.0, 0.0, NAV_GATE_M + 0.01])
    for _ in range(NAV_GATE_STEPS - 1):
        assert not nav.update(k, off, P)
        k += 1
    assert not nav.update(k, P + 0.05, P)  # back within the gate: the count restarts
    for _ in range(NAV_GATE_STEPS - 1):
        k += 1
        assert not nav.update(k, off, P)
    assert nav.update(k + 1, off, P) and nav.failed
    assert not nav.update(k + 2, off, P) and not nav.update(k + 3, P, P) and nav.failed
    assert nav.worst_m == pytest.approx(NAV_GATE_M + 0.01)


def test_at_the_gate_and_noise_never_fail() -> None:
    nav = NavigationCheck(HZ)
    k = _past_grace(nav)
    rng = np.random.default_rng(5)
    at_gate = P + np.array([NAV_GATE_M, 0.0, 0.0])
    assert not any(nav.update(k + i, at_gate, P) for i in range(100))
    assert not any(nav.update(k + 100 + i, P + rng.normal(0.0, 0.3, 3), P) for i in range(1000))
    assert not nav.failed


def test_a_long_gap_gives_the_estimate_time_to_converge_again() -> None:
    """A stall longer than the coast (a stopped daemon): grace again; a shorter gap
    (a starved daemon's usual one) does not reset the count."""
    nav = NavigationCheck(HZ)
    k = _past_grace(nav) + MAX_COAST_PERIODS + 2
    off = P + 3.0
    assert not any(nav.update(k + i, off, P) for i in range(GRACE))
    k += GRACE
    assert not nav.update(k, off, P) and not nav.update(k + 5, off, P)  # a gap of 5
    assert nav.update(k + 10, off, P)


def test_non_finite_estimate_is_a_disagreement() -> None:
    nav = NavigationCheck(HZ, steps=2, grace_s=0.0)
    bad = np.array([np.nan, 0.0, 0.0])
    assert not nav.update(0, bad, P) and nav.update(1, bad, P) and nav.worst_m == np.inf


def test_bad_parameters_are_refused() -> None:
    for hz, gate, steps, grace in ((HZ, 0.0, 3, 1.0), (HZ, -1.0, 3, 1.0),
                                   (HZ, float("nan"), 3, 1.0), (HZ, 2.0, 0, 1.0),
                                   (0, 2.0, 3, 1.0), (HZ, 2.0, 3, -1.0)):
        with pytest.raises(ValueError):
            NavigationCheck(hz, gate, steps, grace)
    with pytest.raises(ValueError):
        NavigationCheck(HZ, every=0)


def test_navigation_fault_holds_then_lands_and_never_returns() -> None:
    loss = RunnerLoss(50, 3.0)
    assert loss.observe(100, 100) is None and not loss.lost
    loss.navigation_fault(2.0)
    assert loss.lost and loss.t_s == 2.0 and loss.t_land == pytest.approx(5.0)
    assert loss.observe(101, 101) is None and loss.lost  # fresh truth: no way back
    assert not loss.commit_due(3.9) and loss.commit_due(4.0)
    loss.commit()
    loss.navigation_fault(6.0)  # a second failure changes nothing
    assert loss.landing and loss.t_s == 2.0


def test_navigation_fault_with_no_landing_holds_for_good() -> None:
    loss = RunnerLoss(50, 0.0)  # never land: hold for good
    loss.navigation_fault(1.0)
    assert loss.lost and loss.t_land is None and not loss.commit_due(1e6)


def test_an_estimate_running_away_during_the_grace_still_fails() -> None:
    """The grace is for converging: a disagreement growing by more than the gate over the
    one the grace started with fails at once (a starved follower whose long gaps kept
    restarting the grace reached 60 m before this rule)."""
    nav = NavigationCheck(HZ)
    err = [5.0 + 0.05 * k for k in range(GRACE)]  # from 5 m, growing 2.5 m/s
    failed_at = next(k for k in range(GRACE) if nav.update(k, P + err[k], P))
    growth = np.sqrt(3) * (err[failed_at] - err[0])
    assert NAV_GATE_M < growth < NAV_GATE_M + 0.3, (failed_at, growth)
    converging = NavigationCheck(HZ)
    assert not any(converging.update(k, P + 50.0 * 0.9**k, P) for k in range(GRACE + 10))


def test_due_every_few_steps_and_never_once_failed() -> None:
    nav = NavigationCheck(HZ, steps=1, grace_s=0.0, every=5)
    assert nav.due(0) and not nav.update(0, P, P)
    assert [k for k in range(1, 12) if nav.due(k)] == [5, 6, 7, 8, 9, 10, 11]
    assert not nav.update(7, P, P) and not nav.due(11) and nav.due(12)
    assert nav.update(12, P + 3.0, P) and not nav.due(100)


@pytest.mark.parametrize(("text", "value"), [("2", 2.0), ("0", 0.0), ("0.001", 0.001),
                                             ("1000", 1000.0), ("0.0005", None), ("-1", None),
                                             ("nan", None), ("inf", None), ("x", None),
                                             ("1001", None)])
def test_nav_gate_flag(text: str, value: float | None) -> None:
    from offboard.cli import nav_gate

    assert nav_gate(text) == value
