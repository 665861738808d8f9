"""Real-time cube8 with seeded packet loss on both transports (issue 13's acceptance run).

Runs ``gcs mission run --realtime --fault-drop P --fault-link both`` (and, with
``--baseline``, the same run without faults) and prints, per run: tracking_rms_m (the
run's own metric, over [formation_deadline_s, end]), the longest span any vehicle spent
out of OFFBOARD, collisions, minimum distance, and the fraction of setpoints that arrived
later than one control period (how well the host kept real time). Medians over
``--repeats`` runs. A benchmark, not a test: the figures depend on the host.

    .venv/bin/python bench/faults_realtime.py --repeats 3 --baseline
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from gcs.mission.run_logs import longest_out_of_offboard

ROOT = Path(__file__).resolve().parents[1]


def one_run(drop: float, duration: float, offset: int, out: Path) -> dict[str, float]:
    argv = [sys.executable, "-m", "gcs.cli", "mission", "run", "scenarios/cube8.toml",
            "--realtime", "--duration", str(duration), "--port-offset", str(offset),
            "--out", str(out)]  # fmt: skip
    if drop > 0.0:
        argv += ["--fault-drop", str(drop), "--fault-link", "both"]
    subprocess.run(argv, cwd=ROOT, check=True, capture_output=True, timeout=duration * 20)
    doc = json.loads((out / "metrics.json").read_text())
    m, sim = doc["metrics"], doc["run"]["simulator"]
    longest = longest_out_of_offboard((out / "vehicle-sim.log").read_text(), duration)
    return {
        "tracking_rms_m": float(m["tracking_rms_m"]),
        "longest_out_of_offboard_s": max(longest.values(), default=0.0),
        "collisions": float(m["collisions"]),
        "min_distance_m": float(m["min_distance_m"]),
        "late_fraction": float(sim["latency"]["late_fraction"]),
    }


def main() -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--drop", type=float, default=0.2, help="loss probability per link")
    ap.add_argument("--duration", type=float, default=25.0, help="simulated seconds")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--baseline", action="store_true", help="also run without faults")
    ap.add_argument("--port-offset", type=int, default=600)
    args = ap.parse_args()
    drops = [args.drop] + ([0.0] if args.baseline else [])
    with tempfile.TemporaryDirectory() as tmp:
        for drop in drops:
            rows = []
            for r in range(args.repeats):
                row = one_run(drop, args.duration, args.port_offset + 20 * r,
                              Path(tmp) / f"d{drop}-{r}")  # fmt: skip
                rows.append(row)
                print(f"drop {drop:.2f} run {r}: " + ", ".join(
                    f"{k} {v:.3f}" for k, v in row.items()), flush=True)
            med = {k: statistics.median(row[k] for row in rows) for k in rows[0]}
            print(f"drop {drop:.2f} median: " + ", ".join(f"{k} {v:.3f}" for k, v in med.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
