"""The distributed run's recorder (gcs.mission.recorder) reads its subscribers' Zenoh channels on
the runner's thread: what is published reaches the arrays at the next drain, garbage and
out-of-run payloads are counted and dropped, and ``finalize`` (before the subscribers are
undeclared) keeps what is still queued. Real Zenoh sessions over loopback TCP."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from conftest import free_tcp_port, wait_for

from gcs.mission.recorder import Recorder
from swarm_common import wire
from swarm_common.scenario.model import load_scenario
from swarm_common.zenoh_session import open_session

SCEN = Path(__file__).resolve().parents[3] / "scenarios"
SWARM = "rec"


def _truth(sc_ids: list[int], k: int, bad: bool = False) -> bytes:
    n = len(sc_ids)
    p = np.arange(3 * n, dtype=float).reshape(n, 3) + k
    if bad:
        p[0, 0] = math.nan
    return wire.encode(wire.Truth(
        step=k, t=k / 50.0, ids=list(sc_ids), p=p, v=np.zeros((n, 3)), att=np.zeros((n, 3)),
        thrust=np.ones(n), lumped=np.zeros((n, 3)), armed=[True] * n, mode=["OFFBOARD"] * n,
    ))


def _estimate(aid: int, k: int) -> bytes:
    return wire.encode(wire.Estimate(
        id=aid, step=k, t=(k + 1) / 50.0, role="follower", z1=np.full(3, float(k)),
        z2=np.ones(3), z3=np.zeros(3), xi=np.zeros(12), zeta=np.zeros(6),
    ))


def _status(aid: int, k: int) -> bytes:
    return wire.encode(wire.Status(
        id=aid, step=k, t=k / 50.0, mode="OFFBOARD", method="dcbf", qp_status="inactive",
        qp_solve_us=3.0, h_min=float(k), lyap_v=0.0, est_health="ok", fallbacks=0,
        u=np.full(3, 0.5),
    ))


def _linked(steps: int) -> tuple[Any, Any, Recorder, list[Any]]:
    """(the runner's session, a publisher's session, a cube8 recorder of ``steps`` steps
    subscribed on the runner's, its subscribers), over loopback TCP."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    runner = open_session(mode="router", listen=[ep])
    other = open_session(connect=[ep])
    rec = Recorder(load_scenario(str(SCEN / "cube8.toml")), steps=steps)
    return runner, other, rec, rec.subscribe(runner, SWARM)


def test_recorder_drains_its_channels_and_counts_garbage() -> None:
    runner, other, rec, subs = _linked(10)
    sc = rec.sc
    aid = sc.ids[3]
    pub_t = other.declare_publisher(wire.key_truth(SWARM))
    pub_e = other.declare_publisher(wire.key_estimate(SWARM, aid))
    pub_s = other.declare_publisher(wire.key_status(SWARM, aid))
    try:
        assert wait_for(lambda: pub_t.matching_status.matching
                        and pub_e.matching_status.matching and pub_s.matching_status.matching)
        for k in range(3):
            pub_t.put(_truth(sc.ids, k))
            pub_e.put(_estimate(aid, k))
            pub_s.put(_status(aid, k))
        pub_t.put(_truth(sc.ids, 4, bad=True))  # non-finite: dropped
        pub_t.put(_truth(sc.ids, 99))  # outside the run's 10 steps: dropped
        pub_s.put(b"\x00not msgpack")  # undecodable: dropped

        def drained() -> bool:
            rec.drain()
            return rec.max_step == 2 and bool(rec.have_status[2, 3]) and rec.dropped == 3

        assert wait_for(drained)
        assert not rec.have_truth[4] and not rec.have_truth[3]
        assert rec.p[2, 0, 0] == np.float32(2.0) and rec.z1[3, 3, 0] == np.float32(2.0)
        assert rec.h_min[1, 3] == np.float32(1.0) and rec.u[2, 3, 1] == np.float32(0.5)
        # queued at the end of a run: finalize (before undeclaring) still records it
        pub_s.put(_status(aid, 6))

        def finalized() -> bool:
            rec.finalize()
            return bool(rec.have_status[6, 3])

        assert wait_for(finalized)
        for s in subs:
            s.undeclare()
        rec.finalize()  # undeclared: nothing more to read, and no error
        assert rec.dropped == 3
    finally:
        other.close()
        runner.close()


def test_a_changed_fence_in_the_truth_reaches_the_verdict() -> None:
    """A truth that reports vehicle 4's newly stored fence: the recorder keeps it with the
    truth's time, and the run's metrics score vehicle 4 against it from then (cube8 has no
    fence of its own, so without it the fence metrics are None)."""
    from gcs.mission.score import recorded_metrics

    runner, other, rec, subs = _linked(3)
    sc = rec.sc
    pub_t = other.declare_publisher(wire.key_truth(SWARM))
    square = np.array([0.0, 0.0, 20.0, 0.0, 20.0, 20.0, 0.0, 20.0])
    try:
        assert wait_for(lambda: pub_t.matching_status.matching)
        for k in range(4):
            msg = wire.decode(_truth(sc.ids, k))
            assert isinstance(msg, wire.Truth)
            if k == 2:
                msg.fences = {sc.ids[3]: square}
            pub_t.put(wire.encode(msg))

        def drained() -> bool:
            rec.drain()
            return rec.max_step == 3

        assert wait_for(drained)
    finally:
        for s in subs:
            s.undeclare()
        other.close()
        runner.close()
    assert rec.fence_changes == [(2 / 50.0, 3, tuple(square))]
    metrics, _ = recorded_metrics(rec, sc, 1.0, 3 / 50.0)
    # vehicle 4 at (11, 12, 13) at t = 0.04 s, the run's last row: 8 m inside the square's
    # y = 20 side (the rows before the change are not scored)
    assert metrics["fence_min_margin_m"] == 20.0 - 12.0
