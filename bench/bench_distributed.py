"""Distributed cube8: lockstep × real time, CPU and RSS per process; real-time latency.

    .venv/bin/python bench/bench_distributed.py [--duration 20] [--port-offset 900]

Prints (no assertions): the lockstep stepping rate (sim seconds per wall second, start-up
excluded), CPU seconds and peak RSS of every process, and for a real-time run the
setpoint-to-odometry latency distribution and the fraction of late cycles (> one
control period) measured by vehicle-sim.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from gcs.mission import run_and_score
from swarm_common.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--port-offset", type=int, default=900)
    ap.add_argument("--skip-realtime", action="store_true")
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    with tempfile.TemporaryDirectory() as tmp:
        doc = run_and_score(sc, Path(tmp) / "lockstep", "rcbf", None, args.duration,
                            port_offset=args.port_offset, show_progress=False)
        run = doc["run"]
        print(f"lockstep cube8 {args.duration:.0f} s: stepping "
              f"{run['stepping_realtime_factor']:.2f}x real time "
              f"(whole run incl. start-up {args.duration / run['wall_s']:.2f}x)")
        steps = args.duration * sc.run.control_hz
        print(f"{'process':14s} {'cpu_s':>7s} {'ms/step':>8s} {'peak RSS MiB':>13s}")
        for name, u in run["processes"].items():
            print(f"{name:14s} {u['cpu_s']:7.2f} {1000 * u['cpu_s'] / steps:8.2f} "
                  f"{u['peak_rss_mib']:13.1f}")
        m = doc["metrics"]
        print(f"min_distance_m {m['min_distance_m']:.3f}  collisions {m['collisions']}")
        if not args.skip_realtime:
            doc = run_and_score(sc, Path(tmp) / "realtime", "rcbf", None, args.duration,
                                realtime=True, port_offset=args.port_offset + 50,
                                show_progress=False)
            lat = doc["run"].get("simulator", {}).get("latency", {})
            print("real-time setpoint-to-odometry latency:", json.dumps(lat))
            m = doc["metrics"]
            print(f"real-time min_distance_m {m['min_distance_m']:.3f}  "
                  f"collisions {m['collisions']}")


if __name__ == "__main__":
    main()
