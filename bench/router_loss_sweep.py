"""Router loss and stall across scenarios and times (no asserts): what the brake-and-hold
and the coordinated landing on odometry keep (docs/security.md, "Losing the runner or
the router").

    .venv/bin/python bench/router_loss_sweep.py [--scenarios cube8 swap_centre ...]
        [--at 6 10 14] [--events kill stall] [--method dcbf]

For every scenario, event time (mission s) and event: the real-time swarm of
tests/realtime_swarm.py (router, simulator, one daemon per agent), then SIGKILL of the
router (``kill``: wait until every vehicle is landed and disarmed) or SIGSTOP for 0.4 s
(``stall``: 4 s more of flight). Prints one line per run: the minimum pairwise distance
before the event and after it (m, the observer's snapshots), the simulator's collision
count, and for ``kill`` the spread of the daemons' land times and the mission time at
which every vehicle was down and disarmed; for ``stall`` how many daemons braked and flew
on.
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from realtime_swarm import collisions, flying_swarm, wait_for  # noqa: E402

PLAN_LINE = re.compile(r"landing on odometry, t_L=([\d.]+) s")
STALL_S = 0.4


def one_run(scenario: str, at: float, event: str, method: str) -> str:
    with tempfile.TemporaryDirectory(prefix="router-sweep-") as tmp:
        run_dir = Path(tmp)
        with flying_swarm(run_dir, at, str(ROOT / "scenarios" / f"{scenario}.toml"),
                          method) as sw:
            obs = sw.obs
            before, _ = obs.reset_min()
            t_event = obs.time_s()
            if event == "kill":
                sw.router.send_signal(signal.SIGKILL)
                wait_for(obs.landed, 120, "every vehicle landed and disarmed")
            else:
                sw.router.send_signal(signal.SIGSTOP)
                time.sleep(STALL_S)
                sw.router.send_signal(signal.SIGCONT)
                wait_for(lambda: obs.time_s() >= t_event + 4.0, 60, "4 s more of flight")
            t_end = obs.time_s()
        texts = [p.read_text() for p in sw.logs]
        head = (f"{scenario:12s} {event:5s} at {t_event:5.2f} s: min distance before "
                f"{before:.3f} m, after {obs.min_dist:.3f} m, collisions {collisions(run_dir)}")
        if event == "kill":
            t_l = [float(m.group(1)) for t in texts if (m := PLAN_LINE.search(t))]
            spread = max(t_l) - min(t_l) if len(t_l) == len(texts) else float("nan")
            return (f"{head}, {len(t_l)}/{len(texts)} land plans (t_L spread {spread:.2f} s), "
                    f"all down and disarmed at t={t_end:.2f} s")
        braked = sum("braking to a hold" in t and "truth back" in t for t in texts)
        return f"{head}, {braked}/{len(texts)} braked and flew on"


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["cube8", "cube8_dist5", "swap_centre"])
    ap.add_argument("--at", nargs="+", type=float, default=[6.0, 10.0, 14.0])
    ap.add_argument("--events", nargs="+", choices=["kill", "stall"], default=["kill", "stall"])
    ap.add_argument("--method", default="dcbf")
    a = ap.parse_args()
    for scenario in a.scenarios:
        if not (ROOT / "scenarios" / f"{scenario}.toml").is_file():
            print(f"router_loss_sweep: no scenario {scenario!r} under scenarios/",
                  file=sys.stderr)
            raise SystemExit(2)
    for scenario in a.scenarios:
        for at in a.at:
            for event in a.events:
                try:
                    print(one_run(scenario, at, event, a.method), flush=True)
                except AssertionError as exc:  # a run that did not get there: say so, go on
                    print(f"{scenario:12s} {event:5s} at {at:5.2f} s: FAILED: {exc}", flush=True)


if __name__ == "__main__":
    main()
