"""offboard.daemon.zenoh.shared_batch.SharedBatch against a batch of each daemon's own
(wire_convert.estimates_from_wire): at every daemon's peer indices, the rows its agent
reads are the same, over random packed steps with shared, conflicting, missing and
foreign payloads."""

from __future__ import annotations

import numpy as np
import pytest

from offboard.daemon.wire_convert import estimates_from_wire
from offboard.daemon.zenoh.shared_batch import SharedBatch
from offboard.estimation.peer_table import EstimateBatch
from swarm_common import wire

N = 12
IDS = list(range(1, N + 1))
INDEX_OF = {aid: j for j, aid in enumerate(IDS)}


def _payload(aid: int, step: int, rng: np.random.Generator) -> wire.Estimate:
    """A decoded estimate, as the process's decode cache hands it to every daemon."""
    return wire.decode(wire.encode(wire.Estimate(
        id=aid, step=step, t=(step + 1) / 50.0, role="leader" if aid <= 2 else "follower",
        z1=rng.normal(size=3), z2=rng.normal(size=3), z3=rng.normal(size=3),
        xi=rng.normal(size=12), zeta=np.zeros(6), cooperative=bool(rng.random() < 0.9),
    )))


def _same_at(a: EstimateBatch, b: EstimateBatch, idx: np.ndarray) -> bool:
    return (np.array_equal(a.t[idx], b.t[idx], equal_nan=True)
            and np.array_equal(a.rows[idx], b.rows[idx])
            and np.array_equal(a.leader[idx], b.leader[idx])
            and np.array_equal(a.cooperative[idx], b.cooperative[idx]))


@pytest.mark.parametrize("seed", range(12))
def test_each_daemon_reads_what_it_received(seed: int) -> None:
    rng = np.random.default_rng(seed)
    daemons = {aid: np.array(sorted(rng.choice(N, 5, replace=False)), dtype=np.int64)
               for aid in IDS}
    shared = SharedBatch(INDEX_OF)
    handed_shared = 0
    for step in range(30):
        published = {aid: _payload(aid, step, rng) for aid in IDS}
        for peers in daemons.values():
            received: dict[int, wire.Estimate] = {}
            for j in peers:
                pid = IDS[int(j)]
                roll = rng.random()
                if roll < 0.1:
                    continue  # lost: this daemon did not receive it
                if roll < 0.15:  # a different payload for the same agent and step
                    received[pid] = _payload(pid, step, rng)
                else:
                    received[pid] = published[pid]
            if rng.random() < 0.1:  # a payload of a non-peer (another key's id)
                other = int(rng.integers(1, N + 1))
                received.setdefault(other, published[other])
            got = shared.batch_for(step, received, peers)
            own = estimates_from_wire(INDEX_OF, N, received)
            assert _same_at(got, own, peers)
            handed_shared += got is shared.batch
    assert handed_shared > 0  # the shared batch is used, not only the fallback


def test_shared_when_daemons_agree_and_own_when_not() -> None:
    rng = np.random.default_rng(1)
    shared = SharedBatch(INDEX_OF)
    e3, e4 = _payload(3, 7, rng), _payload(4, 7, rng)
    peers_a = np.array([2, 3], dtype=np.int64)  # agents 3 and 4
    a = shared.batch_for(7, {3: e3, 4: e4}, peers_a)
    b = shared.batch_for(7, {3: e3}, np.array([2], dtype=np.int64))
    assert a is shared.batch and b is shared.batch
    # agent 4's row is there, but this daemon did not receive it: a batch of its own
    c = shared.batch_for(7, {3: e3}, peers_a)
    assert c is not shared.batch and np.isnan(c.t[3]) and c.t[2] == e3.t
    # a different payload for agent 3 at this step: a batch of its own, with that payload
    other = _payload(3, 7, rng)
    d = shared.batch_for(7, {3: other}, np.array([2], dtype=np.int64))
    assert d is not shared.batch and np.array_equal(d.rows[2], other.block[:21])
    # the next step starts a fresh batch: the one handed out before is never changed
    before = a.rows.copy()
    e = shared.batch_for(8, {3: _payload(3, 8, rng)}, np.array([2], dtype=np.int64))
    assert e is not a and np.array_equal(a.rows, before)
