"""Start-up of a large formation in process: generate, load, set up (no assertions).

    .venv/bin/python bench/bench_large_startup.py [--sizes 256,1024,2048] [--repeats 1]

For each size N, in a fresh child process each repeat (its peak RSS its own):

* generate: wall seconds of ``gcs scenario grid --agents N --leaders L --scramble 1``
  (knn graph, the smallest rigid ``knn_k`` >= 6, L = max(4, round(N/16)) as
  ``bench_scaling.py --leaders auto``), its own loading and gain check included, as a
  subprocess writing the file;
* load: wall seconds of ``load_scenario`` of that file (the loader's checks);
* set-up: wall seconds of ``run_inproc`` for one control period, less its stepping wall
  (the formation, the agents, their observers and gain report, the simulator);
* peak RSS (MiB) of the child after the three.

Prints the 5-million-addition loop's time first, then a table, then one line per size
"N agents: start-up X s" (generate + load + set-up, the median over the repeats) that
``bench_ab.py --figure 'N agents: start-up ([0-9.]+) s'`` reads. The script imports the
code on ``PYTHONPATH`` (or the tree it sits in): ``bench_ab.py`` runs it against a base
revision by its absolute path.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def leaders_for(n: int) -> int:
    """One leader per 16 agents, at least 4 (``bench_scaling.py --leaders auto``)."""
    return max(4, round(n / 16))


def child(n: int) -> dict[str, float]:
    """One start-up of an N-agent grid in this process; its figures."""
    from gcs.mission.inproc import run_inproc
    from swarm_common.scenario.model import load_scenario

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"grid{n}.toml"
        gcs = Path(sys.executable).with_name("gcs")
        argv = [str(gcs), "scenario", "grid", "--agents", str(n), "--leaders",
                str(leaders_for(n)), "--scramble", "1"]
        t0 = time.perf_counter()
        with path.open("w") as out:
            subprocess.run(argv, stdout=out, check=True)
        t1 = time.perf_counter()
        sc = load_scenario(path)
        t2 = time.perf_counter()
        res = run_inproc(sc, "dcbf", duration=sc.control_dt)
        t3 = time.perf_counter()
    stepping = float(res.metrics.get("wall_s", 0.0))
    return {"generate_s": t1 - t0, "load_s": t2 - t1, "setup_s": t3 - t2 - stepping,
            "rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def loop_s() -> float:
    """The 5-million-addition loop at module level (best of three; docs/performance.md)."""
    code = "import time\nt=time.perf_counter()\nx=0\nfor i in range(5000000): x+=1\n" \
           "print(time.perf_counter()-t)"
    return min(float(subprocess.run([sys.executable, "-c", code], capture_output=True,
                                    text=True, check=True).stdout) for _ in range(3))


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="256,1024,2048")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    opts = ap.parse_args()
    if opts.child is not None:
        print(json.dumps(child(opts.child)))
        return
    sizes = [int(x) for x in opts.sizes.split(",") if x]
    if not sizes or min(sizes) < 3 or opts.repeats < 1:
        ap.error("--sizes: agent counts >= 3; --repeats >= 1")
    print(f"5-million-addition loop: {loop_s():.2f} s")
    env = dict(os.environ)
    env.setdefault("PYTHONPATH", str(HERE))
    rows: dict[int, list[dict[str, float]]] = {}
    for n in sizes:
        for _ in range(opts.repeats):
            out = subprocess.run([sys.executable, __file__, "--child", str(n)], env=env,
                                 capture_output=True, text=True, check=True)
            rows.setdefault(n, []).append(json.loads(out.stdout.strip().splitlines()[-1]))
    print("| agents, leaders | generate s | load s | set-up s | peak RSS MiB |")
    print("|---|---|---|---|---|")
    med = {n: {k: statistics.median(r[k] for r in rs) for k in rs[0]} for n, rs in rows.items()}
    for n, m in med.items():
        print(f"| {n}, {leaders_for(n)} | {m['generate_s']:.1f} | {m['load_s']:.1f} | "
              f"{m['setup_s']:.1f} | {m['rss_mib']:.0f} |")
    for n, m in med.items():
        print(f"{n} agents: start-up {m['generate_s'] + m['load_s'] + m['setup_s']:.1f} s")


if __name__ == "__main__":
    main()
