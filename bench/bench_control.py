"""Control-step benchmark: per-agent step (sensing + DESO + reference observer + QP) and the
in-process cube8 mission's real-time factor.

    python bench/bench_control.py [--duration 60] [--profile-s 20]

Timings wrap the real methods during an in-process RCBF run (time.perf_counter), so they
include Python call overhead. "QP (OSQP called)" is SafetyQP.solve when the nominal input
violates a constraint; otherwise the exact shortcut returns in a few µs ("QP all").
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gcs.inproc import run_inproc  # noqa: E402
from offboard import agent as agent_mod  # noqa: E402
from offboard.clf_rcbf import SafetyQP  # noqa: E402
from offboard.deso import DESO  # noqa: E402
from offboard.reference import DesiredStateObserver  # noqa: E402
from offboard.sensing import Sensor  # noqa: E402
from swarm_common.enums import Method  # noqa: E402
from swarm_common.scenario import load_scenario  # noqa: E402


def _wrap(cls, name, store, key):
    orig = getattr(cls, name)

    def timed(self, *a, **k):
        t0 = time.perf_counter()
        out = orig(self, *a, **k)
        store.setdefault(key, []).append((time.perf_counter() - t0) * 1e6)
        return out

    setattr(cls, name, timed)
    return orig


def stats(x: list[float]) -> str:
    a = np.asarray(x)
    return f"median {np.median(a):7.1f} µs  p99 {np.percentile(a, 99):7.1f} µs  (n = {len(a)})"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--profile-s", type=float, default=20.0)
    a = ap.parse_args()
    sc = load_scenario(a.scenario)
    # 1. real-time factor, no instrumentation
    for m in Method:
        r = run_inproc(sc, m, duration=a.duration)
        print(f"in-process {sc.name} {a.duration:.0f} s [{m}]: wall {r.metrics['wall_s']:.2f} s, "
              f"{r.metrics['realtime_factor']:.1f}x real time")
    # 2. per-component timings (instrumented RCBF run)
    store: dict[str, list[float]] = {}
    saved = [
        (agent_mod.FollowerAgent, "step", _wrap(agent_mod.FollowerAgent, "step", store, "total")),
        (Sensor, "measure", _wrap(Sensor, "measure", store, "sensing")),
        (DESO, "update", _wrap(DESO, "update", store, "deso")),
        (DesiredStateObserver, "update", _wrap(DesiredStateObserver, "update", store, "ref")),
    ]
    r = run_inproc(sc, "rcbf", duration=a.profile_s)
    for cls, name, orig in saved:
        setattr(cls, name, orig)
    s = r.series
    f = [i for i, ag in enumerate(sc.agents) if not ag.is_leader]
    solve = s.solve_us[:, f]
    osqp_called = solve[(s.fallback[:, f]) | (solve > 0)]
    print(f"per-agent control step (follower, rcbf, {a.profile_s:.0f} s):")
    print(f"  total step      {stats(store['total'])}")
    print(f"  sensing         {stats(store['sensing'])}")
    print(f"  DESO            {stats(store['deso'])}")
    print(f"  reference obs.  {stats(store['ref'])}")
    print(f"  QP all steps    {stats(list(solve.reshape(-1)))}")
    del osqp_called
    # OSQP-only timing on the active steps: re-time SafetyQP.solve calls that reach OSQP
    active: list[float] = []
    orig = SafetyQP.solve

    def timed(self, *args, **kw):
        res = orig(self, *args, **kw)
        if res.status != "inactive":
            active.append(res.solve_us)
        return res

    SafetyQP.solve = timed
    run_inproc(sc, "rcbf", duration=a.profile_s)
    SafetyQP.solve = orig
    if active:
        print(f"  QP, OSQP called {stats(active)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
