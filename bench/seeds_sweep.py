"""Seed sweep: every method over N seeds (sensor noise, initial estimate errors, ζ).

    python bench/seeds_sweep.py [SCENARIO] [--seeds 20] [--jobs 2] [--duration S] [--out F.json]

Prints the markdown distribution table (docs/paper-mapping.md) and per-run lines.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gcs.report.sweep import seeds_table  # noqa: E402
from swarm_common.enums import Method  # noqa: E402

METHODS = [str(m) for m in Method]


def _one(job: tuple[str, str, int, float | None]) -> tuple[str, int, dict]:
    from gcs.mission.inproc import run_inproc
    from swarm_common.scenario.model import load_scenario

    path, method, seed, dur = job
    return method, seed, run_inproc(load_scenario(path), method, seed=seed, duration=dur).metrics


def main() -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("scenario", nargs="?", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    jobs = [(a.scenario, m, a.first + s, a.duration) for s in range(a.seeds) for m in METHODS]
    t0 = time.time()
    with ProcessPoolExecutor(max_workers=a.jobs) as ex:
        res = list(ex.map(_one, jobs))
    dist = {m: [r for mm, _, r in res if mm == m] for m in METHODS}
    for m, s, r in res:
        print(f"{m:5s} seed {s:3d}: min {r['min_distance_m']:.3f} m, coll {r['collisions']}, "
              f"formed {r['formation_time_s']}, trk max {r['tracking_max_m']}, "
              f"fallbacks {r['qp_fallbacks']}", file=sys.stderr)
    print(seeds_table(dist))
    print(f"{len(jobs)} runs in {time.time() - t0:.0f} s", file=sys.stderr)
    if a.out:
        Path(a.out).write_text(json.dumps({"runs": [[m, s, r] for m, s, r in res]}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
