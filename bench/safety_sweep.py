"""Safety sweep: true-barrier statistics of rcbf vs dcbf over scenarios and seeds.

    python bench/safety_sweep.py [--scenarios cube8 swap_centre ...] [--methods rcbf dcbf]
                                 [--seeds 10] [--duration 30] [--jobs 2] [--out F.json]

Each run is in-process (gcs.mission.inproc.run_inproc, as ``gcs mission run --inproc --seed N
--method M``). From the ground truth: true h_min (m²), (pair, step) samples with h < 0,
follower-step fraction with h < 0, min distance (m, over the physics steps), collisions,
formation time (s), tracking rms (m), follower-steps whose input was clipped by the
setpoint conversion. Prints one markdown table: median and worst over seeds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENARIOS = ["cube8", "swap_centre", "grid12", "cube8_dist5", "cube8_noise5"]
# (key, header, worst = max or min)
COLUMNS = [
    ("h_min", "true h_min (m²)", min),
    ("neg_steps", "pair-steps h<0", max),
    ("neg_frac", "follower-steps h<0 (%)", max),
    ("min_distance_m", "min dist (m)", min),
    ("collisions", "collisions", max),
    ("formation_time_s", "formation (s)", max),
    ("tracking_rms_m", "tracking rms (m)", max),
    ("clipped", "clipped steps", max),
]


def one(job: tuple[str, str, int, float]) -> dict[str, Any]:
    """Run one (scenario, method, seed, duration) and return its row."""
    from gcs.mission.inproc import run_inproc
    from gcs.report.safety_metrics import clipped_steps, true_barrier
    from offboard.estimation.bearing import formation_from_scenario
    from swarm_common.scenario.model import load_scenario

    name, method, seed, dur = job
    # cube8_noise5 is outside the load-time noise bound on purpose (docs/safety.md)
    sc = load_scenario(ROOT / "scenarios" / f"{name}.toml", allow_unsafe=True)
    res = run_inproc(sc, method, seed=seed, duration=dur)
    fol = formation_from_scenario(sc).follower_idx
    s = res.series
    tb = true_barrier(s.p, s.v, fol, sc.controller.tau_safe_s, sc.controller.d_safe_m,
                      sc.controller.dcbf_vertical_scale)
    m = res.metrics
    return {
        "scenario": name, "method": method, "seed": seed, "h_min": tb.h_min,
        "neg_steps": tb.neg_pair_steps, "neg_frac": 100.0 * tb.neg_follower_frac,
        "min_distance_m": m["min_distance_m"], "collisions": m["collisions"],
        "formation_time_s": m["formation_time_s"], "tracking_rms_m": m["tracking_rms_m"],
        "clipped": clipped_steps(s.u, fol, sc.vehicle),
    }


def _fmt(vals: list[Any], worst: Any) -> str:
    """'median / worst'; a run that never formed (None) is the worst ('never')."""
    if any(v is None for v in vals):
        ok = [v for v in vals if v is not None]
        med = f"{statistics.median(ok):.3g}" if len(ok) > len(vals) / 2 else "never"
        return f"{med} / never ({len(vals) - len(ok)} runs)"
    return f"{statistics.median(vals):.3g} / {worst(vals):.3g}"


def table(rows: list[dict[str, Any]]) -> str:
    """Markdown table, one line per (scenario, method): median / worst over seeds."""
    out = ["| scenario | method | " + " | ".join(h for _, h, _ in COLUMNS) + " |",
           "|---|---|" + "---|" * len(COLUMNS)]
    keys = sorted({(r["scenario"], r["method"]) for r in rows},
                  key=lambda k: (SCENARIOS.index(k[0]) if k[0] in SCENARIOS else 99, k[1]))
    for sc, me in keys:
        sel = [r for r in rows if r["scenario"] == sc and r["method"] == me]
        cells = [_fmt([r[k] for r in sel], w) for k, _, w in COLUMNS]
        out.append(f"| {sc} | {me} ({len(sel)} seeds) | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=SCENARIOS)
    ap.add_argument("--methods", nargs="+", default=["rcbf", "dcbf"])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    jobs = [(s, m, a.first + k, a.duration)
            for s in a.scenarios for k in range(a.seeds) for m in a.methods]
    t0 = time.time()
    with ProcessPoolExecutor(max_workers=a.jobs) as ex:
        rows = list(ex.map(one, jobs))
    print(table(rows))
    print(f"{len(jobs)} runs of {a.duration:g} s in {time.time() - t0:.0f} s", file=sys.stderr)
    if a.out:
        Path(a.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
