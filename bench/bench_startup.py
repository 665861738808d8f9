"""Start-up of a distributed run: children forked from the preloaded server against one
interpreter per child (``SWARM_LAUNCH=exec``), alternated on the same machine.

    .venv/bin/python bench/bench_startup.py [--repeats 3] [--duration 2] [--processes N]

Each repeat runs ``gcs mission run scenarios/cube8.toml --duration D`` from the shell once
with each launch (fork, exec, fork, exec, ...) and prints, per launch, the medians of:
the wall time of the whole command; the CPU seconds each child had used when the run's
first step was recorded (``processes_at_first_step`` in metrics.json: the start-up, the
children's imports and kernel loading included); and their sum over the children.
Prints the 5-million-addition loop's time first (docs/performance.md). No assertions.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GCS = [sys.executable, "-m", "gcs.cli"]
RUNNER = "gcs (router + recorder)"


def loop_time() -> float:
    """Best of three: a pure-Python loop of 5 million additions, at module level."""
    code = ("import time\nt=time.perf_counter()\nx=0\nfor i in range(5_000_000): x+=i\n"
            "print(time.perf_counter()-t)")
    return min(float(subprocess.run([sys.executable, "-c", code], capture_output=True,
                                    text=True, check=True).stdout) for _ in range(3))


def one_run(launch: str, duration: float, processes: int | None) -> tuple[float, list[float]]:
    """(wall s of the command, CPU s of each child at the first step)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        argv = [*GCS, "mission", "run", str(ROOT / "scenarios" / "cube8.toml"),
                "--duration", str(duration), "--out", str(out), "--json"]
        if processes:
            argv += ["--processes", str(processes)]
        env = {**os.environ, "SWARM_LAUNCH": launch}
        t0 = time.perf_counter()
        r = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if r.returncode != 0:
            raise SystemExit(f"{launch}: exit {r.returncode}: {r.stderr[-500:]}")
        run = json.loads((out / "metrics.json").read_text())["run"]
        first = run.get("processes_at_first_step") or {}
        return wall, [v["cpu_s"] for k, v in first.items() if k != RUNNER]


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--processes", type=int, default=None)
    args = ap.parse_args()
    print(f"5-million-addition loop: {loop_time():.2f} s")
    walls: dict[str, list[float]] = {"fork": [], "exec": []}
    child_cpu: dict[str, list[float]] = {"fork": [], "exec": []}
    sums: dict[str, list[float]] = {"fork": [], "exec": []}
    for _ in range(args.repeats):
        for launch in ("fork", "exec"):
            wall, cpu = one_run(launch, args.duration, args.processes)
            walls[launch].append(wall)
            child_cpu[launch] += cpu
            sums[launch].append(sum(cpu))
    packing = (f"{args.processes} daemon processes" if args.processes
               else "one process per agent")
    print(f"cube8, {args.duration:g} s mission, {args.repeats} runs per launch, {packing}")
    print(f"{'launch':<6} {'wall s (median)':>16} {'child CPU s at first step':>26} "
          f"{'all children':>13}")
    for launch in ("fork", "exec"):
        print(f"{launch:<6} {statistics.median(walls[launch]):16.2f} "
              f"{statistics.median(child_cpu[launch]):26.2f} "
              f"{statistics.median(sums[launch]):13.2f}")
    ratio = statistics.median(walls["exec"]) / statistics.median(walls["fork"])
    print(f"wall exec / fork: {ratio:.2f}")


if __name__ == "__main__":
    main()
