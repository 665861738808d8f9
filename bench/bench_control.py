"""Control-core benchmark: per-agent step and the in-process mission's real-time factor.

    python bench/bench_control.py [--scenario scenarios/cube8.toml] [--duration 20]
                                  [--profile-s 20] [--repeats 2] [--methods dcbf,rcbf,apf]

Prints, with no assertions (figures for docs/performance.md, "In process"):

1. in-process mission × real time per method (``run_inproc``, no instrumentation), each
   run ``--repeats`` times (the 2-core machine is shared: give the range);
2. per-agent step (``FollowerAgent.step`` and ``LeaderAgent.step``, wrapped with
   time.perf_counter, so Python call overhead is included) in µs, median and p99, over
   the steps where no QP solver was called (the nominal input already satisfied every
   row, or, dcbf, one row alone was active and solved exactly), over all steps (solver
   calls included) and over the steps with a solver call alone (DAQP, or OSQP: the
   number of OSQP solves is printed as well);
3. the follower step's parts: sensing, DESO update, desired-state observer.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gcs.mission.inproc import run_inproc  # noqa: E402
from offboard.agent.factory import FollowerAgent  # noqa: E402
from offboard.agent.leader import LeaderAgent  # noqa: E402
from offboard.estimation.deso import DESO  # noqa: E402
from offboard.estimation.reference import DesiredStateObserver  # noqa: E402
from offboard.estimation.sensing import Sensor  # noqa: E402
from offboard.safety.rcbf import clf_rcbf  # noqa: E402
from swarm_common.scenario.model import Scenario, load_scenario  # noqa: E402

Store = dict[str, list[float]]


# QP solves so far (offboard.safety.rcbf.clf_rcbf._ClfRowsQP._solve_rows, counted)
_solver_calls = [0]
_osqp_calls = [0]  # of which OSQP solves (offboard.safety.rcbf.clf_rcbf.update_solve, counted)


def _wrap(cls: Any, name: str, store: Store, key: str) -> Callable[..., Any]:
    """Replace ``cls.name`` by a timed wrapper appending µs to ``store[key]``; returns the
    original. Agent steps also record whether a QP solver ran during the step
    (``key + ":solver"``: 1.0 / 0.0): a solve was made, not merely an active QP (the dcbf
    QP solves a single active row exactly, without a solver)."""
    orig = getattr(cls, name)

    def timed(self: Any, *a: Any, **k: Any) -> Any:
        calls = _solver_calls[0]
        t0 = time.perf_counter()
        out = orig(self, *a, **k)
        store.setdefault(key, []).append((time.perf_counter() - t0) * 1e6)
        if getattr(out, "status", None) is not None:
            store.setdefault(key + ":solver", []).append(
                1.0 if _solver_calls[0] > calls else 0.0)
            store.setdefault(key + ":t", []).append(float(a[1]))  # step(k, t, ...): t (s)
        return out

    setattr(cls, name, timed)
    return orig


def _count_solves() -> tuple[Callable[..., Any], Callable[..., Any]]:
    """Count QP solves (both QPs solve in ``_ClfRowsQP._solve_rows``) and OSQP's among them
    (``offboard.safety.rcbf.clf_rcbf.update_solve``); returns the originals."""
    orig_rows, orig_osqp = clf_rcbf._ClfRowsQP._solve_rows, clf_rcbf.update_solve

    def rows(*a: Any, **k: Any) -> Any:
        _solver_calls[0] += 1
        return orig_rows(*a, **k)

    def osqp(*a: Any, **k: Any) -> Any:
        _osqp_calls[0] += 1
        return orig_osqp(*a, **k)

    clf_rcbf._ClfRowsQP._solve_rows = rows  # type: ignore[method-assign]
    clf_rcbf.update_solve = osqp
    return orig_rows, orig_osqp


def stats(x: list[float] | np.ndarray) -> str:
    a = np.asarray(x, dtype=float)
    if a.size == 0:
        return "(no samples)"
    return f"median {np.median(a):7.1f} µs  p99 {np.percentile(a, 99):7.1f} µs  (n = {a.size})"


def slow_tail(us: np.ndarray, t: np.ndarray, bin_s: float = 0.5) -> None:
    """Print the slowest follower step (µs, at t) and where the slowest 1 % of steps lie:
    the 0.5 s windows of mission time holding most of them (a cluster there is work that
    some event, such as an outage, brings into the control loop)."""
    worst = int(np.argmax(us))
    cut = np.percentile(us, 99)
    tail_t = t[us > cut]
    bins, counts = np.unique(np.floor(tail_t / bin_s) * bin_s, return_counts=True)
    top = sorted(zip(counts.tolist(), bins.tolist(), strict=True), reverse=True)[:3]
    where = ", ".join(f"{c} in [{b:.1f}, {b + bin_s:.1f}) s" for c, b in top)
    print(f"  follower, slowest step     {us[worst]:7.1f} µs at t = {t[worst]:.2f} s; "
          f"slowest 1 % ({tail_t.size}): {where}")


def realtime(sc: Scenario, method: str, duration: float, repeats: int) -> None:
    """Print wall time and × real time of ``repeats`` uninstrumented in-process runs."""
    xs = []
    for _ in range(repeats):
        r = run_inproc(sc, method, duration=duration)
        xs.append(r.metrics["realtime_factor"])
        print(f"in-process {sc.name} {duration:.0f} s [{method}]: wall "
              f"{r.metrics['wall_s']:.2f} s, {r.metrics['realtime_factor']:.1f}x real time")
    print(f"  -> {sc.name} [{method}]: {min(xs):.1f}-{max(xs):.1f}x real time")


def per_agent(sc: Scenario, method: str, duration: float) -> None:
    """Print the instrumented per-agent figures of one in-process run."""
    store: Store = {}
    targets = [(FollowerAgent, "step", "follower"), (LeaderAgent, "step", "leader"),
               (Sensor, "measure", "sensing"), (DESO, "update", "deso"),
               (DesiredStateObserver, "update", "ref")]
    saved = [(cls, name, _wrap(cls, name, store, key)) for cls, name, key in targets]
    rows, osqp_call = _count_solves()
    _solver_calls[0] = _osqp_calls[0] = 0
    try:
        run_inproc(sc, method, duration=duration)
    finally:
        for cls, name, orig in saved:
            setattr(cls, name, orig)
        clf_rcbf._ClfRowsQP._solve_rows = rows  # type: ignore[method-assign]
        clf_rcbf.update_solve = osqp_call
    f = np.asarray(store.get("follower", []))
    solved = np.asarray(store.get("follower:solver", []), dtype=bool)
    lead = store.get("leader", [])
    print(f"per-agent control step [{method}], {sc.name}, {duration:.0f} s "
          f"(QP solves {_solver_calls[0]}, of which OSQP {_osqp_calls[0]}):")
    print(f"  follower, no solver call   {stats(f[~solved])}")
    print(f"  follower, all steps        {stats(f)}")
    print(f"  follower, solver called    {stats(f[solved])}  "
          f"({solved.mean() * 100:.1f} % of steps)"
          if solved.size else "  follower, solver called    (no samples)")
    if f.size:
        slow_tail(f, np.asarray(store.get("follower:t", []), dtype=float))
    print(f"  leader                     {stats(lead)}")
    print(f"  sensing                    {stats(store.get('sensing', []))}")
    print(f"  DESO update                {stats(store.get('deso', []))}")
    print(f"  desired-state observer     {stats(store.get('ref', []))}")


def main() -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--duration", type=float, default=20.0, help="s per real-time run")
    ap.add_argument("--profile-s", type=float, default=20.0, help="s of the timed run")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--methods", default="dcbf,rcbf,apf")
    a = ap.parse_args()
    try:
        sc = load_scenario(a.scenario)
    except (OSError, ValueError) as exc:
        print(f"bench_control: {exc}", file=sys.stderr)
        return 2
    methods = [m.strip() for m in a.methods.split(",") if m.strip()]
    for m in methods:
        realtime(sc, m, a.duration, max(1, a.repeats))
    for m in methods:
        per_agent(sc, m, a.profile_s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
