"""The Zenoh feed against a second session on loopback (peer that listens)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import free_tcp_port, wait_for  # noqa: E402

from gcs.dashboard.zenoh_feed import ZenohFeed
from swarm_common.wire import (
    Command,
    Estimate,
    Status,
    Truth,
    decode,
    encode,
    key_cmd,
    key_estimate,
    key_status,
    key_truth,
)
from swarm_common.zenoh_session import open_session


def status(i: int, **kw) -> Status:
    base = dict(
        id=i,
        step=1,
        t=0.02,
        mode="OFFBOARD",  # the vehicle flies the agent: its events count
        method="rcbf",
        qp_status="solved",
        qp_solve_us=80.0,
        h_min=0.4,
        lyap_v=0.1,
        est_health="ok",
        fallbacks=0,
    )
    base.update(kw)
    return Status(**base)


@pytest.fixture
def sessions():
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    sim = open_session(listen=[ep])
    feed = ZenohFeed("t1", ids=[1, 2, 3], connect=[ep], stale_s=0.5).start()
    yield sim, feed
    feed.close()
    sim.close()


def test_feed_receives_and_marks_missing(sessions):
    sim, feed = sessions
    truth = Truth(
        step=3,
        t=0.06,
        ids=[1, 2, 3],
        p=np.arange(9.0).reshape(3, 3),
        v=np.zeros((3, 3)),
        att=np.zeros((3, 3)),
        thrust=np.ones(3),
        lumped=np.zeros((3, 3)),
        armed=[True] * 3,
        mode=["OFFBOARD"] * 3,
    )
    est = Estimate(
        id=2,
        step=3,
        t=0.08,
        role="follower",
        z1=np.ones(3),
        z2=np.zeros(3),
        z3=np.zeros(3),
        xi=np.zeros(12),
    )

    def pump():  # the dialling peer may need a moment: keep publishing
        sim.put(key_truth("t1"), encode(truth))
        sim.put(key_status("t1", 1), encode(status(1)))
        sim.put(key_status("t1", 2), encode(status(2)))
        sim.put(key_estimate("t1", 2), encode(est))
        return feed.truth is not None and 2 in feed.estimate and {1, 2} <= set(feed.status)

    assert wait_for(pump)
    snap = feed.snapshot()
    assert snap.truth.step == 3 and np.allclose(snap.truth.p[2], [6, 7, 8])
    assert snap.missing == [3]
    assert np.allclose(snap.estimate[2][0].z1, 1.0)

    # transitions become events
    feed.drain_events()
    sim.put(key_status("t1", 1), encode(status(1, method="apf", fallbacks=2, comm_ok=False)))
    assert wait_for(lambda: feed.status[1][0].method == "apf")
    kinds = {e.kind for e in feed.drain_events()}
    assert {"method", "fallback", "comm"} <= kinds

    # garbage, wrong version, id/key mismatch: counted, not fatal
    sim.put(key_status("t1", 2), b"\x00\x01garbage")
    sim.put(key_status("t1", 3), encode(status(2)))
    assert wait_for(lambda: feed.bad_payloads >= 2)
    assert 3 not in feed.status

    # status going stale
    time.sleep(0.6)
    feed.check()
    assert set(feed.missing()) == {1, 2, 3}
    assert any(e.kind == "status" and "stale" in e.text for e in feed.drain_events())


def test_feed_publishes_commands(sessions):
    sim, feed = sessions
    got: list[tuple[str, Command]] = []
    sub = sim.declare_subscriber(
        key_cmd("t1", "*"),
        lambda s: got.append((str(s.key_expr), decode(s.payload.to_bytes()))),
    )
    try:

        def send():
            feed.switch_method("apf", agent=0)
            return bool(got)

        assert wait_for(send)
        key, cmd = got[-1]
        assert key == key_cmd("t1", "method") and cmd.method == "apf" and cmd.agent == 0
        feed.inject_outage(1.5, agent=4)
        # send() may have published several method commands; wait for the outage itself
        outage_key = key_cmd("t1", "outage")
        assert wait_for(lambda: any(k == outage_key for k, _ in got))
        cmd = next(c for k, c in got if k == outage_key)
        assert cmd.duration_s == 1.5 and cmd.agent == 4
        with pytest.raises(ValueError):
            feed.switch_method("magic")
    finally:
        sub.undeclare()


def truth_at(step: int) -> Truth:
    return Truth(
        step=step, t=0.02 * step, ids=[1, 2, 3], p=np.zeros((3, 3)), v=np.zeros((3, 3)),
        att=np.zeros((3, 3)), thrust=np.ones(3), lumped=np.zeros((3, 3)),
        armed=[True] * 3, mode=["OFFBOARD"] * 3,
    )


def test_a_stalled_feed_on_the_router_session_does_not_stall_the_router():
    """``gcs dashboard --launch`` runs its feed on the swarm router's own session. While
    the feed cannot take in anything (its lock held here: a dashboard busy or descheduled
    on a loaded host), the router still forwards every truth from the simulator to the
    daemons, and the feed catches up with the newest once it runs again. With a Python
    callback as the subscriber's handler (zenoh-python queues the samples for the
    callback's thread, about 256 of them), the router forwarded nothing more once that
    queue was full: the daemons got truth up to step 258 of 1000 here until the lock was
    released."""
    from gcs.mission.router import open_router

    LAST = 1000
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router([ep])
    feed = ZenohFeed("t3", ids=[1, 2, 3], session=router).start()
    sim = open_session("client", connect=[ep])
    daemon = open_session("client", connect=[ep])
    got: list[int] = []
    sub = daemon.declare_subscriber(key_truth("t3"), lambda s: got.append(
        decode(s.payload.to_bytes()).step))

    def both_hear() -> bool:  # the clients may need a moment to reach the router
        sim.put(key_truth("t3"), encode(truth_at(1)))
        return bool(got) and feed.truth is not None

    def send_last() -> bool:
        sim.put(key_truth("t3"), encode(truth_at(LAST)))
        return True

    try:
        assert wait_for(both_hear)
        with feed._lock:  # the feed's reader stops at its first sample from here on
            for k in range(2, LAST + 1):  # 4 times the ring, and any queue of ~256
                sim.put(key_truth("t3"), encode(truth_at(k)))
            # the newest truth is forwarded while the feed is stuck (sent again while it
            # has not arrived: a put may be dropped by a congested sender)
            assert wait_for(lambda: send_last() and LAST in got, timeout=15.0), (
                f"daemon got up to {max(got)}")
        assert wait_for(lambda: send_last() and feed.truth is not None
                        and feed.truth.step == LAST)
    finally:
        sub.undeclare()
        feed.close()
        daemon.close()
        sim.close()
        router.close()


def test_a_sample_that_breaks_a_handler_is_counted_and_reading_goes_on(sessions):
    sim, feed = sessions
    ingest, broken = feed.ingest, []

    def breaks_once(key: str, data: bytes) -> None:
        if not broken:
            broken.append(key)
            raise KeyError("a handler's bug")
        ingest(key, data)

    feed.ingest = breaks_once

    def pump() -> bool:  # the dialling peer may need a moment: keep publishing
        sim.put(key_truth("t1"), encode(truth_at(7)))
        return feed.truth is not None

    assert wait_for(pump)
    assert broken and feed.bad_payloads >= 1 and feed.truth.step == 7
