"""Mission benchmark: what a formation mission costs per control step against the paper's
cube8 (issue: "a mission run costs no more per step than today's cube8 run").

    python bench/bench_mission.py [--duration 30] [--repeats 5] [--method dcbf]
                                  [--mission scenarios/course8.toml]

Runs cube8 (the sinusoid) and the mission scenario in process, alternately (A B A B ..., so a
drift of the shared machine's speed hits both), each ``--duration`` s from its start, and
prints per scenario the median wall time per control step (µs, all agents), the median
× real time, and the median of the pairwise ratios mission / cube8. No assertions.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gcs.mission.inproc import run_inproc  # noqa: E402
from swarm_common.scenario.model import load_scenario  # noqa: E402


def one(path: Path, method: str, duration: float) -> float:
    """Wall seconds of one in-process run's stepping (the runner's own wall_s)."""
    res = run_inproc(load_scenario(path), method, duration=duration)
    return float(res.metrics["wall_s"])


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--method", default="dcbf")
    ap.add_argument("--mission", type=Path, default=ROOT / "scenarios" / "course8.toml")
    a = ap.parse_args()
    cube = ROOT / "scenarios" / "cube8.toml"
    steps = round(a.duration * load_scenario(cube).run.control_hz)
    one(cube, a.method, 1.0), one(a.mission, a.method, 1.0)  # warm-up: kernels, caches
    walls: dict[str, list[float]] = {"cube8": [], a.mission.stem: []}
    for _ in range(a.repeats):
        walls["cube8"].append(one(cube, a.method, a.duration))
        walls[a.mission.stem].append(one(a.mission, a.method, a.duration))
    for name, w in walls.items():
        med = statistics.median(w)
        print(f"{name:10s} {a.method}: {1e6 * med / steps:7.1f} µs per control step "
              f"(median of {len(w)}, {min(w):.2f}-{max(w):.2f} s), "
              f"{a.duration / med:5.1f}x real time")
    ratio = statistics.median(m / c for m, c in zip(walls[a.mission.stem], walls["cube8"],
                                                     strict=True))
    print(f"ratio {a.mission.stem} / cube8 per step: median {ratio:.3f}")


if __name__ == "__main__":
    main()
