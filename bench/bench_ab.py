"""Two codes side by side: one benchmark run alternately on a base revision and this tree.

    .venv/bin/python bench/bench_ab.py [--base REV] [--rounds 3] [--figure REGEX] \\
        [--together] -- bench/bench_distributed.py --skip-realtime --method dcbf [--processes 2]

A speed-up is claimed only as a ratio of two codes run alternately on one machine (issue
44; docs/performance.md): machines of the same kind differ by more than most changes do,
and a shared machine drifts within minutes. This script makes that ratio.

* The base is checked out as a ``git worktree`` in a temporary folder (removed at the end);
  it runs with this tree's interpreter and virtual environment, ``PYTHONPATH`` set to the
  tree, from the tree's root, so the benchmark script and every process it starts import
  that tree's code. The default base is :data:`ISSUE44_BASE`, the code the scale-out
  issue's figures were measured on.
* Each tree runs the command once as a warm-up (its compiled kernels are cached per source
  path, so a fresh worktree compiles them all), then ``--rounds`` times, alternating
  base, new, base, new, ... With ``--together`` each round starts both runs at once
  instead: for a single-process benchmark on two cores, each run has a core and both see
  the same moment of a shared machine, which resolved differences that alternated runs
  could not (docs/performance.md, "Side by side").
* From each run's output ``--figure`` (a regular expression with one group) takes the last
  match as a float: by default the ``× real time`` figure the stepping benchmarks print
  (``bench_distributed.py``'s "stepping 4.2x real time", ``bench_scaling.py``'s and
  ``bench_control.py``'s "40.9x real time").

Prints every run's figure, the median of each tree, and the median and range of the paired
ratios new / base (round i's new against round i's base). No assertions: figures for
docs/performance.md. A run that fails or prints no figure stops the script (exit 1).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The code the scale-out issue (44) was filed against (its figures): the last commit
# before this round of issues began (559d1fc, the house).
ISSUE44_BASE = "210ca2a"
DEFAULT_FIGURE = r"([0-9]+(?:\.[0-9]+)?)x real time"


def start_run(tree: Path, command: list[str]) -> subprocess.Popen[str]:
    """Start ``command`` from ``tree`` with ``PYTHONPATH=tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    return subprocess.Popen([sys.executable, *command], cwd=tree, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def finish_run(proc: subprocess.Popen[str], tree: Path, command: list[str],
               figure: re.Pattern[str], timeout: float) -> float:
    """Wait for a run of :func:`start_run`; the figure it printed."""
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        stdout, stderr = proc.communicate()
    out = stdout + stderr
    found = figure.findall(out)
    if proc.returncode != 0 or not found:
        tail = "\n".join(out.strip().splitlines()[-5:])
        raise SystemExit(f"bench_ab: {' '.join(command)} in {tree} exited "
                         f"{proc.returncode}, figure {'found' if found else 'not found'}:\n{tail}")
    return float(found[-1])


def run_once(tree: Path, command: list[str], figure: re.Pattern[str], timeout: float) -> float:
    """Run ``command`` from ``tree`` with ``PYTHONPATH=tree``; the figure it printed."""
    return finish_run(start_run(tree, command), tree, command, figure, timeout)


def add_worktree(rev: str, where: Path) -> Path:
    """A detached worktree of ``rev`` under ``where``."""
    tree = where / "base"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), rev],
                   check=True)
    return tree


def remove_worktree(tree: Path) -> None:
    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                   check=False)
    shutil.rmtree(tree, ignore_errors=True)


def paired_ratios(base: list[float], new: list[float]) -> list[float]:
    """new_i / base_i for each round (figures where larger is faster)."""
    return [n / b for b, n in zip(base, new, strict=True)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--base", default=ISSUE44_BASE, help=f"base revision (default {ISSUE44_BASE})")
    ap.add_argument("--rounds", type=int, default=3, help="alternated pairs (default 3)")
    ap.add_argument("--figure", default=DEFAULT_FIGURE,
                    help="regex with one group: the figure (larger is faster)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per run")
    ap.add_argument("--no-warmup", action="store_true", help="skip each tree's warm-up run")
    ap.add_argument("--together", action="store_true",
                    help="start each round's two runs at once, one per core, instead of "
                         "one after the other (a single-process benchmark on 2 cores)")
    ap.add_argument("command", nargs=argparse.REMAINDER,
                    help="-- then the benchmark script and its arguments, relative to a tree")
    args = ap.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command or args.rounds < 1:
        ap.error("give --rounds >= 1 and a command after --")
    figure = re.compile(args.figure)
    with tempfile.TemporaryDirectory(prefix="bench_ab_") as tmp:
        base_tree = add_worktree(args.base, Path(tmp))
        try:
            trees = {"base": base_tree, "new": ROOT}
            if not args.no_warmup:
                for name, tree in trees.items():
                    print(f"# warm-up {name}: {run_once(tree, command, figure, args.timeout):.2f}",
                          flush=True)
            got: dict[str, list[float]] = {"base": [], "new": []}
            for r in range(args.rounds):
                if args.together:  # both started, then both read
                    procs = {name: start_run(tree, command) for name, tree in trees.items()}
                    for name, tree in trees.items():
                        got[name].append(finish_run(procs[name], tree, command, figure,
                                                    args.timeout))
                else:
                    for name, tree in trees.items():
                        got[name].append(run_once(tree, command, figure, args.timeout))
                for name in trees:
                    print(f"# round {r + 1} {name}: {got[name][-1]:.2f}", flush=True)
        finally:
            remove_worktree(base_tree)
    ratios = paired_ratios(got["base"], got["new"])
    print(f"command: {' '.join(command)}")
    print(f"base {args.base}: " + ", ".join(f"{x:.2f}" for x in got["base"])
          + f" (median {statistics.median(got['base']):.2f})")
    print("new (this tree): " + ", ".join(f"{x:.2f}" for x in got["new"])
          + f" (median {statistics.median(got['new']):.2f})")
    print(f"new / base, paired: median {statistics.median(ratios):.3f} "
          f"(range {min(ratios):.3f}–{max(ratios):.3f}, {len(ratios)} pairs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
