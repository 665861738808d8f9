"""The daemons' Zenoh receive path in one packed process, without the rest of the run.

    .venv/bin/python bench/bench_bus.py [--agents 64] [--peers 14] [--steps 400]
        [--layout shared|own] [--seed 1]

One Zenoh session (no network: no listen, no connect, no multicast) holds ``--agents``
:class:`offboard.daemon.zenoh.link.SwarmBus` objects, each with a :class:`PayloadGuard` and
``--peers`` peers (the leaders 1-4 and random others), as in a packed process. Each step
every agent puts one estimate payload; then every bus moves its reference to the step
(``set_reference``) and pumps what arrived, exactly as the packed daemons do.
``--layout own``: each bus holds subscriptions of its own, as a daemon alone in its
process does (and as packed daemons did before the thirteenth round); ``shared``: one
subscriber per key for all of them (:mod:`offboard.daemon.zenoh.shared_subs`, pumped once per step).
Prints (no assertions) the medians, over the steps after the first 50, of the main
thread's CPU per agent-step spent receiving (pump and reference) and per put. Every
payload must be accepted by every subscriber: the bench fails loudly if any is dropped
or missing.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from offboard.daemon.link_guard import PayloadGuard  # noqa: E402
from offboard.daemon.zenoh.link import FIFO_DEPTH, SwarmBus  # noqa: E402
from offboard.daemon.zenoh.shared_subs import SharedSubscriptions  # noqa: E402
from swarm_common import wire  # noqa: E402
from swarm_common.zenoh_session import open_session  # noqa: E402

SWARM = "bench"
LEADERS = [1, 2, 3, 4]
WARMUP_STEPS = 50


def payload(aid: int, step: int, rng: np.random.Generator) -> bytes:
    return wire.encode(wire.Estimate(
        id=aid, step=step, t=(step + 1) / 50.0,
        role="leader" if aid in LEADERS else "follower", z1=rng.normal(size=3),
        z2=rng.normal(size=3), z3=np.zeros(3), xi=rng.normal(size=12), zeta=np.zeros(6),
    ))


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=64)
    ap.add_argument("--peers", type=int, default=14)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--layout", choices=["shared", "own"], default="shared")
    ap.add_argument("--seed", type=int, default=1)
    opts = ap.parse_args()
    if not 5 <= opts.agents <= 256 or not 4 <= opts.peers < opts.agents:
        print("bench_bus: --agents must be 5..256 and --peers 4..agents-1", file=sys.stderr)
        sys.exit(2)
    if opts.steps <= WARMUP_STEPS:
        print(f"bench_bus: --steps must exceed {WARMUP_STEPS}", file=sys.stderr)
        sys.exit(2)
    rng = np.random.default_rng(opts.seed)
    ids = list(range(1, opts.agents + 1))
    session = open_session()
    shared = SharedSubscriptions(session, FIFO_DEPTH) if opts.layout == "shared" else None
    buses = []
    expected = 0
    for aid in ids:
        guard = PayloadGuard(ids, LEADERS, 50.0, aid)
        others = [j for j in ids if j not in LEADERS and j != aid]
        extra = rng.choice(others, opts.peers - len(LEADERS), replace=False).tolist()
        peers = sorted({*LEADERS, *extra} - {aid})
        expected += len(peers)
        buses.append(SwarmBus(session, SWARM, aid, guard, peers=peers, shared=shared))
    pubs = {aid: session.declare_publisher(wire.key_estimate(SWARM, aid)) for aid in ids}
    time.sleep(0.5)
    recv_us, put_us = [], []
    for step in range(opts.steps):
        data = [payload(aid, step, rng) for aid in ids]
        t0 = time.thread_time()
        for aid, blob in zip(ids, data, strict=True):
            pubs[aid].put(blob)
        put_us.append((time.thread_time() - t0) * 1e6 / len(ids))
        time.sleep(0.002)  # Zenoh delivers asynchronously
        t0 = time.thread_time()
        if shared is not None:
            shared.pump()
        for bus in buses:
            bus.set_reference(step)
            bus.pump(with_shared=False)
        recv_us.append((time.thread_time() - t0) * 1e6 / len(ids))
        got = sum(len(b.estimates.get(step, {})) for b in buses)
        if got != expected or any(b.drops.total for b in buses):
            print(f"bench_bus: step {step}: {got} of {expected} estimates kept, "
                  f"{sum(b.drops.total for b in buses)} dropped", file=sys.stderr)
            os._exit(1)
    r, p = np.array(recv_us[WARMUP_STEPS:]), np.array(put_us[WARMUP_STEPS:])
    print(f"{opts.agents} agents, {opts.peers} peers each, layout {opts.layout}, "
          f"{opts.steps - WARMUP_STEPS} steps measured")
    print(f"receive (pump + set_reference), CPU per agent-step: median {np.median(r):.1f} us "
          f"(p90 {np.percentile(r, 90):.1f})")
    print(f"put, CPU per payload: median {np.median(p):.2f} us")
    sys.stdout.flush()
    os._exit(0)  # Zenoh's teardown takes seconds and measures nothing


if __name__ == "__main__":
    main()
