"""What a run's ``vehicle-sim.log`` says about flight modes (simulation time ``t=``).

Used by the real-time fault benchmark and its test: every vehicle's spans out of OFFBOARD
after it first entered OFFBOARD (a failsafe, a third party's mode change).
"""

from __future__ import annotations

import re

MODE_LINE = re.compile(r"t=(\d+(?:\.\d+)?) vehicle (\d+): mode (\S+) -> (\S+)")


def vehicles_in_offboard(sim_log: str) -> set[int]:
    """The vehicles that entered OFFBOARD at least once."""
    return {int(v) for _, v, _, new in MODE_LINE.findall(sim_log) if new == "OFFBOARD"}


def out_of_offboard_spans(sim_log: str, end_s: float) -> dict[int, list[tuple[float, float]]]:
    """Per vehicle, the (start, end) simulation-time spans (s) out of OFFBOARD after it
    first entered OFFBOARD (a span still open at the end of the log ends at ``end_s``)."""
    spans: dict[int, list[tuple[float, float]]] = {}
    left: dict[int, float] = {}
    entered: set[int] = set()
    for m in MODE_LINE.finditer(sim_log):
        t, vid, old, new = float(m[1]), int(m[2]), m[3], m[4]
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
