"""What a distributed run's child processes said in their logs.

* ``vehicle-sim.log``, flight modes (simulation time ``t=``): used by the real-time fault
  benchmark and its test, every vehicle's spans out of OFFBOARD after it first entered
  OFFBOARD (a failsafe, a third party's mode change).
* ``offboard-*.log``, the lockstep waits a daemon gave up (:func:`lockstep_gaps`): a
  neighbour's estimate or odometry not heard within ``neighbour_timeout`` (the neighbour
  is declared lost and the step taken without it), or no truth for a step. The run may
  then differ from the in-process one; the runner puts them in the run's facts.
"""

from __future__ import annotations

import re
from pathlib import Path

MODE_LINE = re.compile(r"t=(\d+(?:\.\d+)?) vehicle (\d+): mode (\S+) -> (\S+)")
# what each kind of gap looks like in a daemon's log (offboard.daemon.drivers,
# offboard.daemon.sensing_source): (agent, neighbour, step) groups; truth has no neighbour
GAP_LINES = {
    "estimate": re.compile(r"agent (\d+): neighbour (\d+) silent at step (\d+): lost"),
    "odometry": re.compile(r"agent (\d+): no odometry of (\d+) at step (\d+):"),
    "truth": re.compile(r"agent (\d+): no truth for step (\d+)()"),
}
GAPS_KEPT = 100  # the first gaps a run's facts list (their count is kept in full)


def vehicles_in_offboard(sim_log: str) -> set[int]:
    """The vehicles that entered OFFBOARD at least once."""
    return {int(v) for _, v, _, new in MODE_LINE.findall(sim_log) if new == "OFFBOARD"}


def out_of_offboard_spans(sim_log: str, end_s: float) -> dict[int, list[tuple[float, float]]]:
    """Per vehicle, the (start, end) simulation-time spans (s) out of OFFBOARD after it
    first entered OFFBOARD, within the run: a span still open at ``end_s`` (the run's
    duration) ends there, and the modes the log records after it (the shutdown, where
    the daemons stop first and the vehicles fail safe) are not the run's."""
    spans: dict[int, list[tuple[float, float]]] = {}
    left: dict[int, float] = {}
    entered: set[int] = set()
    for m in MODE_LINE.finditer(sim_log):
        t, vid, old, new = float(m[1]), int(m[2]), m[3], m[4]
        if t > end_s:
            continue
        if new == "OFFBOARD":
            entered.add(vid)
            if vid in left:
                spans.setdefault(vid, []).append((left.pop(vid), t))
        elif old == "OFFBOARD" and vid in entered:
            left[vid] = t
    for vid, t0 in left.items():
        spans.setdefault(vid, []).append((t0, end_s))
    return spans


def longest_out_of_offboard(sim_log: str, end_s: float) -> dict[int, float]:
    """Per vehicle that left OFFBOARD, its longest span out of it (s)."""
    spans = out_of_offboard_spans(sim_log, end_s)
    return {vid: max(b - a for a, b in s) for vid, s in spans.items()}


def lockstep_gaps(run_dir: Path) -> tuple[int, list[dict[str, int | str]]]:
    """Every lockstep wait the daemons of the run in ``run_dir`` logged as given up: their
    count and the first :data:`GAPS_KEPT` as ``{"kind", "agent", "neighbour", "step"}``
    (``neighbour`` 0 for truth), ordered by step, agent, kind. A log that cannot be read
    counts nothing."""
    found: list[tuple[int, int, str, int]] = []
    for path in sorted(run_dir.glob("offboard-*.log")):
        try:
            text = path.read_text(errors="replace")
        except OSError:
            continue
        for kind, line in GAP_LINES.items():
            for a, j, k in line.findall(text):
                step, other = (int(j), 0) if kind == "truth" else (int(k), int(j))
                found.append((step, int(a), kind, other))
    found.sort()
    return len(found), [{"kind": kind, "agent": a, "neighbour": j, "step": k}
                        for k, a, kind, j in found[:GAPS_KEPT]]
