"""offboard.daemon.link_guard: stamp and field validators, Zenoh payload guard, the non-blocking
command retry, the OFFBOARD keeper (start-up and failsafe recovery policy)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.daemon.link_guard import (
    MAX_JUMP_PERIODS,
    REANCHOR_COUNT,
    STEP_AHEAD,
    CommandRetry,
    DropLog,
    PayloadGuard,
    StampGuard,
    odometry_fields_ok,
)
from offboard.daemon.mavlink.offboard_keeper import Backoff, OffboardKeeper, VehicleView
from swarm_common import wire

HZ = 50
DT_US = 20_000
IDS = [1, 2, 3, 4]
LEADERS = [1, 2]
IN_PROGRESS = 5


# -- ODOMETRY ------------------------------------------------------------------------------
def test_forged_far_future_stamp_is_dropped_and_the_clock_goes_on() -> None:
    g = StampGuard(HZ, lockstep=True)
    assert g.check(0, 0.0) is None
    assert g.check(DT_US, 0.02) is None
    assert g.check(2**62, 0.03) == "implausible stamp jump"
    assert g.check(2 * DT_US, 0.04) is None  # the real stream is not disturbed
    assert g.last_us == 2 * DT_US


def test_duplicate_and_backwards_stamps() -> None:
    g = StampGuard(HZ, lockstep=True)
    assert g.check(10 * DT_US, 0.0) is None
    assert g.check(10 * DT_US, 0.0) == "duplicate stamp"
    assert g.check(9 * DT_US, 0.0) == "non-monotonic stamp"
    assert g.check(-1, 0.0) == "negative stamp"


def test_lockstep_jump_bound_and_reanchor() -> None:
    g = StampGuard(HZ, lockstep=True)
    g.check(0, 0.0)
    assert g.check(MAX_JUMP_PERIODS * DT_US, 100.0) is None  # wall time does not matter
    base = 10_000 * DT_US
    for i in range(REANCHOR_COUNT - 1):
        assert g.check(base + i * DT_US, 100.0) == "implausible stamp jump"
    assert g.check(base + (REANCHOR_COUNT - 1) * DT_US, 100.0) is None
    assert g.reanchors == 1


def test_scattered_forgeries_never_reanchor() -> None:
    g = StampGuard(HZ, lockstep=True)
    g.check(0, 0.0)
    for i in range(10):
        assert g.check(2**40 + i * 2**30, 0.0) == "implausible stamp jump"
        assert g.check(2**62 - i, 0.0) == "implausible stamp jump"
    assert g.last_us == 0


def test_realtime_allows_what_the_wall_clock_allows() -> None:
    g = StampGuard(HZ, lockstep=False)
    g.check(0, 10.0)
    assert g.check(2_000_000, 12.0) is None  # 2 s stopped daemon, the sim went on
    assert g.check(2_100_000, 12.0) is None  # queued stamps read at once, a gap among them
    assert g.check(2_500_000, 12.1) is None  # within the lead allowance
    assert g.check(60_000_000, 12.1) == "implausible stamp jump"
    assert g.check(2**62, 12.1) == "implausible stamp jump"


def test_first_stamp_bound() -> None:
    assert StampGuard(HZ, True).check(2**62, 0.0) == "first stamp implausible"


@pytest.mark.parametrize(
    ("pos", "q", "vel", "why"),
    [
        ((0, 0, -5), (1, 0, 0, 0), (0, 0, 0), None),
        ((math.nan, 0, 0), (1, 0, 0, 0), (0, 0, 0), "non-finite field"),
        ((0, 0, 0), (1, 0, 0, 0), (math.inf, 0, 0), "non-finite field"),
        ((1e9, 0, 0), (1, 0, 0, 0), (0, 0, 0), "position out of range"),
        ((0, 0, 0), (1, 0, 0, 0), (0, 5e3, 0), "velocity out of range"),
        ((0, 0, 0), (2, 0, 0, 0), (0, 0, 0), "quaternion not unit"),
    ],
)
def test_odometry_fields(pos: tuple, q: tuple, vel: tuple, why: str | None) -> None:
    assert odometry_fields_ok(pos, q, vel) == why


# -- Zenoh payloads ------------------------------------------------------------------------
def _truth(step: int, t: float | None = None, ids: list[int] | None = None) -> wire.Truth:
    n = len(ids or IDS)
    return wire.Truth(step=step, t=step / HZ if t is None else t, ids=list(ids or IDS),
                      p=np.zeros((n, 3)), v=np.zeros((n, 3)), att=np.zeros((n, 3)),
                      thrust=np.zeros(n), lumped=np.zeros((n, 3)), armed=[True] * n,
                      mode=["OFFBOARD"] * n, collisions=0)


def _est(aid: int, step: int, z1: np.ndarray | None = None) -> wire.Estimate:
    return wire.Estimate(id=aid, step=step, t=(step + 1) / HZ,
                         role="leader" if aid in LEADERS else "follower",
                         z1=np.zeros(3) if z1 is None else z1, z2=np.zeros(3),
                         z3=np.zeros(3), xi=np.zeros(12), zeta=np.zeros(6))


def test_payload_guard_windows_around_own_step() -> None:
    g = PayloadGuard(IDS, LEADERS, HZ, own_id=3)
    assert g.check(_truth(5000)) is None  # before the first ODOMETRY: any sane step
    assert g.check(_truth(2**40)) is not None
    g.ref = 100
    assert g.check(_truth(100)) is None
    assert g.check(_truth(100 + STEP_AHEAD + 1)) is not None
    assert g.check(_truth(2**40)) is not None
    assert g.check(_est(1, 99)) is None
    assert g.check(_est(1, 2**40)) is not None
    assert g.check(_est(1, -1)) is None  # the initial estimate of a late starter


def test_payload_guard_fields() -> None:
    g = PayloadGuard(IDS, LEADERS, HZ, own_id=3)
    g.ref = 10
    assert g.check(_truth(10, t=99.0)) is not None  # t does not match the step
    assert g.check(_truth(10, ids=[1, 2, 3, 9])) is not None
    bad = _truth(10)
    bad.p[0, 0] = math.nan
    assert g.check(bad) is not None
    assert g.check(_est(9, 10)) is not None  # not an agent of the scenario
    assert g.check(_est(1, 10, z1=np.array([math.inf, 0, 0]))) is not None
    fake_role = _est(3, 10)
    fake_role.role = "leader"
    assert g.check(fake_role) is not None
    assert g.check(wire.Command(kind="outage", agent=0, duration_s=1.0)) is None
    assert g.check(wire.Command(kind="outage", agent=0, duration_s=math.inf)) is not None
    assert g.check(wire.Command(kind="land", agent=42)) is not None


def test_drop_log_counts_every_drop_and_logs_rate_limited(caplog: pytest.LogCaptureFixture) -> None:
    d = DropLog("x", every_s=5.0)
    with caplog.at_level("WARNING"):
        for i in range(100):
            d.drop("r", "detail", now=i * 0.01)
    assert d.counts == {"r": 100} and d.total == 100
    assert len(caplog.records) == 1
    d.drop("r", "detail", now=10.0)
    assert len(caplog.records) == 2 and "dropped 100" in caplog.records[-1].getMessage()


# -- commands ------------------------------------------------------------------------------
def test_command_retry_attempts_and_ack() -> None:
    r = CommandRetry(command=176, params=[], attempts=3, timeout_s=1.0)
    assert r.due(0.0) and r.attempt == 0
    assert not r.due(0.5)  # never blocks: just "not yet"
    assert r.due(1.0) and r.attempt == 1
    r.on_ack(IN_PROGRESS, 1.5, IN_PROGRESS)
    assert not r.due(2.2) and not r.done  # in progress restarts the wait
    r.on_ack(0, 2.3, IN_PROGRESS)
    assert r.done and r.result == 0 and not r.expired


def test_command_retry_expires() -> None:
    r = CommandRetry(command=176, params=[], attempts=2, timeout_s=1.0)
    sent = [t for t in (0.0, 0.5, 1.0, 1.5, 2.0, 3.0) if r.due(t)]
    assert sent == [0.0, 1.0] and r.expired and r.result is None


def test_backoff_doubles_and_resets() -> None:
    b = Backoff(first_s=0.5, max_s=2.0)
    assert b.ready(0.0)
    b.failed(0.0)
    assert not b.ready(0.4) and b.ready(0.5)
    b.failed(0.5)
    b.failed(1.5)
    b.failed(3.5)
    assert b.delay == 2.0
    b.reset()
    assert b.ready(0.0)


# -- OFFBOARD keeper -----------------------------------------------------------------------
def _view(offboard: bool, hold: bool = False, texts: int = 0, armed: bool = True,
          streaming: float = 5.0) -> VehicleView:
    return VehicleView(offboard, hold, armed, texts, streaming)


def _started() -> OffboardKeeper:
    k = OffboardKeeper(stream_s=0.6, manual_start=False)
    assert k.decide(0.0, _view(False, armed=False, streaming=0.1)) is None  # stream first
    assert k.decide(1.0, _view(False, armed=False)) == "offboard"
    k.result("offboard", True, 1.0)
    assert k.decide(1.1, _view(True, armed=False)) == "arm"
    k.result("arm", True, 1.1)
    assert k.decide(1.2, _view(True)) is None and k.startup_done
    return k


def test_failsafe_hold_is_recovered_with_backoff() -> None:
    k = _started()
    assert k.decide(5.0, _view(False, hold=True, texts=1, streaming=0.0)) is None
    assert k.recovering
    assert k.decide(6.0, _view(False, hold=True, texts=1)) == "offboard"
    k.result("offboard", False, 6.0)  # refused: wait 0.5 s, then 1 s
    assert k.decide(6.2, _view(False, hold=True, texts=1)) is None
    assert k.decide(6.6, _view(False, hold=True, texts=1)) == "offboard"
    k.result("offboard", True, 6.6)
    assert k.decide(7.5, _view(True, texts=1)) is None
    assert k.recoveries == 1 and not k.recovering


def test_own_fault_explains_a_hold_without_statustext() -> None:
    k = _started()
    k.fault(9.5)
    k.decide(10.0, _view(False, hold=True))
    assert k.recovering


def test_third_party_land_and_hold_are_respected() -> None:
    k = _started()
    for t in np.arange(5.0, 10.0, 0.1):
        assert k.decide(float(t), _view(False, hold=False)) is None  # LAND
    k2 = _started()
    for t in np.arange(5.0, 10.0, 0.1):
        assert k2.decide(float(t), _view(False, hold=True)) is None  # HOLD, no failsafe
    assert k2.respect


def test_recovery_stops_when_a_third_party_lands_it() -> None:
    k = _started()
    k.decide(5.0, _view(False, hold=True, texts=1))
    assert k.recovering
    assert k.decide(5.5, _view(False, hold=False, texts=1)) is None
    assert not k.recovering
    assert k.decide(9.0, _view(False, hold=True, texts=2)) is None  # still respected


def test_failsafe_between_offboard_and_arm_is_recovered() -> None:
    """OFFBOARD accepted, then the offboard-loss failsafe put the vehicle in HOLD before
    the arm was accepted: once armed, OFFBOARD is asked for again (it was never
    recovered before: the keeper had not 'seen' OFFBOARD)."""
    k = OffboardKeeper(stream_s=0.6, manual_start=False)
    assert k.decide(1.0, _view(False, armed=False)) == "offboard"
    k.result("offboard", True, 1.0)
    # the failsafe hits before any heartbeat shows OFFBOARD
    assert k.decide(1.1, _view(False, hold=True, texts=1, armed=False)) == "arm"
    k.result("arm", True, 1.1)
    k.decide(1.2, _view(False, hold=True, texts=1))
    assert k.startup_done and k.recovering
    assert k.decide(1.3, _view(False, hold=True, texts=1)) == "offboard"


def test_failsafe_whose_statustext_was_lost_is_recovered_from_the_heartbeat() -> None:
    """20 % loss can drop the failsafe STATUSTEXT; the HEARTBEAT's MAV_STATE_CRITICAL
    (repeated every second) is evidence enough, so the HOLD is not taken for a third
    party's and respected forever."""
    k = _started()
    for t in np.arange(5.0, 8.0, 0.1):
        k.decide(float(t), VehicleView(False, True, True, 0, 5.0, critical=True))
    assert k.recovering and not k.respect


def _ground_station_start(now: float, **evidence: object) -> str | None:
    """A ``--manual-start`` daemon (its ground station sends OFFBOARD and arm): the
    vehicle went to OFFBOARD and armed, then this daemon stopped for longer than the
    offboard-loss timeout before its loop sampled a HEARTBEAT that showed OFFBOARD. After
    it resumes, the vehicle is armed in HOLD; what the keeper asks for at ``now``."""
    k = OffboardKeeper(stream_s=0.6, manual_start=True)
    assert k.decide(1.0, _view(False, armed=False)) is None  # on its pad, nothing asked
    evidence.setdefault("failsafe_texts", 0)
    held = VehicleView(False, True, True, streaming_s=5.0, **evidence)  # type: ignore[arg-type]
    want = None
    for t in np.arange(4.0, now + 1e-9, 0.1):
        want = k.decide(float(t), held) or want
    return want


def test_manual_start_failsafe_before_the_daemon_saw_offboard_is_recovered() -> None:
    """The vehicle's own word that it was in OFFBOARD: a HEARTBEAT that said so (read in
    the backlog after the stop, never sampled by the loop), or its failsafe STATUSTEXT
    naming offboard. Without either (a HOLD the daemon cannot place) it is left alone."""
    assert _ground_station_start(6.0, failsafe_texts=1, offboard_lost_texts=1) == "offboard"
    assert _ground_station_start(6.0, reported_offboard=True, critical=True) == "offboard"
    assert _ground_station_start(6.0, failsafe_texts=1, critical=True) is None
    assert _ground_station_start(6.0, reported_offboard=True) is None  # HOLD, no evidence


def test_no_warning_while_the_heartbeat_still_shows_the_old_mode(
    caplog: pytest.LogCaptureFixture,
) -> None:
    k = OffboardKeeper(stream_s=0.6, manual_start=False)
    assert k.decide(1.0, _view(False, armed=False)) == "offboard"
    k.result("offboard", True, 1.0)
    assert k.decide(1.1, _view(False, armed=False)) == "arm"
    k.result("arm", True, 1.1)
    with caplog.at_level("WARNING"):
        for t in (1.2, 1.5, 1.9):  # armed, heartbeat still POSCTL: nothing to judge yet
            assert k.decide(t, _view(False, hold=False)) is None
    assert not k.respect and not caplog.records


def test_all_finite_one_reduction_per_array() -> None:
    from offboard.daemon.link_guard import all_finite

    ok = (np.zeros(3), np.full((4, 3), 3.4e38), np.array([-3.4e38]))
    assert all_finite(ok)
    assert all_finite(())
    for bad in (np.nan, np.inf, -np.inf):
        arr = np.zeros(9)
        arr[4] = bad
        assert not all_finite((np.ones(3), arr))
    # +inf and -inf in different arrays do not cancel into a finite sum
    assert not all_finite((np.array([np.inf]), np.array([-np.inf])))


def test_decoded_estimate_is_judged_by_its_block() -> None:
    """A decoded estimate's vectors are views of one block, judged by one sum; a non-finite
    value in any of its 27 floats on the wire makes it non-finite, and an estimate built
    from separate arrays is judged vector by vector."""
    from offboard.daemon.link_guard import payload_finite

    good = wire.Estimate(id=2, step=7, t=0.14, role="follower", z1=np.ones(3),
                         z2=np.ones(3), z3=np.ones(3), xi=np.ones(12), zeta=np.ones(6))
    assert good.block is None and payload_finite(good)
    got = wire.decode(wire.encode(good))
    assert isinstance(got, wire.Estimate) and got.block is not None
    for v in (got.z1, got.z2, got.z3, got.xi, got.zeta):
        assert np.shares_memory(v, got.block)
    assert payload_finite(got)
    for pos in range(27):
        x = np.ones(27)
        x[pos] = np.nan if pos % 2 else np.inf
        bad = wire.Estimate(id=2, step=7, t=0.14, role="follower", z1=x[0:3].copy(),
                            z2=x[3:6].copy(), z3=x[6:9].copy(), xi=x[9:21].copy(),
                            zeta=x[21:27].copy())
        assert not payload_finite(bad), pos
        dec = wire.decode(wire.encode(bad))
        assert isinstance(dec, wire.Estimate) and dec.block is not None
        assert not payload_finite(dec), pos
