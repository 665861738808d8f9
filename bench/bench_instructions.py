"""Instructions per in-process control step, counted by valgrind (callgrind), not timed.

    .venv/bin/python bench/bench_instructions.py [--scenario scenarios/cube8.toml]
        [--method dcbf] [--short 2] [--long 6]

On a shared 2-core machine the wall-clock benchmarks move by ±15 % between runs of the
same code, more than most single changes to the control step. This one counts the
machine instructions instead (callgrind's ``Ir``), which repeat to a few parts in 10⁴:

1. the mission is imported and run once for ``--long`` seconds uninstrumented, so that
   every kernel the counted runs call is compiled or loaded from numba's cache before
   (a kernel first compiled inside a counted run adds about a billion instructions to
   it), OSQP and the caches warm;
2. instrumentation is switched on (``callgrind_control -i on``) and ``run_inproc`` runs
   ``--short`` then ``--long`` seconds of mission, the counters dumped after each;
3. the difference of the two counts, divided by the steps between them, is the cost of a
   control step of the whole swarm (agents, simulator, recording), start-up excluded.

Prints the instructions per control step and per agent-step; asserts nothing. Needs
valgrind (exit 2 with a one-line message without it). ``PYTHONHASHSEED`` is fixed so
that two runs of the same code count the same. Compare two trees by running each.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import sys, time, os
sys.path.insert(0, {root!r})
from gcs.mission.inproc import run_inproc
from swarm_common.scenario.model import load_scenario
sc = load_scenario({scenario!r})
run_inproc(sc, duration=max({durations!r}), method={method!r})
def mark(name):
    open(os.path.join({tmp!r}, name), "w").close()
def wait(name):
    while not os.path.exists(os.path.join({tmp!r}, name)):
        time.sleep(0.05)
mark("ready")
for i, d in enumerate({durations!r}):
    wait(f"go{{i}}")
    run_inproc(sc, duration=d, method={method!r})
    mark(f"done{{i}}")
wait("stop")
"""


def _wait_for(path: Path, proc: subprocess.Popen[bytes], what: str) -> None:
    while not path.exists():
        if proc.poll() is not None:
            raise SystemExit(f"bench_instructions: the run ended before {what}")
        time.sleep(0.2)


def count(scenario: str, method: str | None, durations: list[float]) -> list[int]:
    """Callgrind ``Ir`` of each ``run_inproc`` of ``durations`` (s), in order."""
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        child = tmp / "child.py"
        child.write_text(CHILD.format(root=str(ROOT), scenario=scenario, method=method,
                                      tmp=tmp_s, durations=durations))
        out = tmp / "callgrind.out"
        env = {**os.environ, "PYTHONHASHSEED": "0"}
        proc = subprocess.Popen(
            ["valgrind", "--tool=callgrind", "--instr-atstart=no",
             f"--callgrind-out-file={out}", sys.executable, str(child)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
        )
        try:
            _wait_for(tmp / "ready", proc, "it was ready")

            def ctl(*args: str) -> None:
                subprocess.run(["callgrind_control", *args, str(proc.pid)], check=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

            ctl("-i", "on")
            for i in range(len(durations)):
                ctl("-z")
                (tmp / f"go{i}").touch()
                _wait_for(tmp / f"done{i}", proc, f"run {i} ended")
                ctl("-d")
            ctl("-i", "off")
            (tmp / "stop").touch()
            proc.wait(timeout=600)
        finally:
            if proc.poll() is None:
                proc.kill()
        dumps = sorted(tmp.glob("callgrind.out.*"), key=lambda p: int(p.suffix[1:]))
        totals = []
        for d in dumps:
            for line in d.read_text().splitlines():
                if line.startswith("totals:"):
                    totals.append(int(line.split()[1]))
        if len(totals) != len(durations):
            raise SystemExit(f"bench_instructions: {len(totals)} counts for "
                             f"{len(durations)} runs")
        return totals


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--method", default=None, help="default: the scenario's")
    ap.add_argument("--short", type=float, default=2.0, help="s of mission, first run")
    ap.add_argument("--long", type=float, default=6.0, help="s of mission, second run")
    a = ap.parse_args()
    if shutil.which("valgrind") is None or shutil.which("callgrind_control") is None:
        print("bench_instructions: valgrind (callgrind) is not installed", file=sys.stderr)
        raise SystemExit(2)
    if not 0.0 < a.short < a.long <= 600.0:
        print("bench_instructions: need 0 < --short < --long <= 600", file=sys.stderr)
        raise SystemExit(2)
    sys.path.insert(0, str(ROOT))
    from swarm_common.scenario.model import load_scenario

    sc = load_scenario(a.scenario)
    short, long_ = count(a.scenario, a.method, [a.short, a.long])
    steps = round((a.long - a.short) / sc.control_dt)
    per_step = (long_ - short) / steps
    print(f"{sc.name} [{a.method or sc.controller.method}]: {short / 1e9:.4f} G instructions "
          f"in {a.short:g} s, {long_ / 1e9:.4f} G in {a.long:g} s")
    print(f"  per control step {per_step / 1e6:.3f} M, per agent-step "
          f"{per_step / sc.n / 1e3:.1f} k ({steps} steps, {sc.n} agents)")


if __name__ == "__main__":
    main()
