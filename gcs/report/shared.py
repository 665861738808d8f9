"""What every report shares: the methods' labels, the paper's Table 3, the formation
tolerance, the legend format and the closest approach of a run."""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_common.enums import Method

PAPER_TABLE3: dict[str, tuple[float, float]] = {
    Method.RCBF: (0.75, 236.41),
    Method.APF: (0.37, 1115.23),
    Method.NONE: (0.10, 189.52),
}
LABELS: dict[str, str] = {
    Method.RCBF: "Proposed RCBF",
    Method.DCBF: "Sampled-data CBF (ours)",
    Method.APF: "Improved APF",
    Method.NONE: "No collision avoidance",
}
FORMED_TOL_M = 0.1  # gcs.report.metrics.formation_time tolerance


def md_legend(rows: list[tuple[str, str]]) -> str:
    """A markdown definition list: one ``* **column**: meaning`` line per column."""
    return "".join(f"* **{name}**: {text}\n" for name, text in rows)


def closest_approach(s: dict) -> tuple[int, float, tuple[int, int]]:
    """(index, distance m, vehicle index pair) of the run's smallest pair distance."""
    k = int(np.argmin(s["min_dist"]))
    p = s["p"][k]
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    d[np.diag_indices(len(p))] = np.inf
    a, b = np.unravel_index(int(np.argmin(d)), d.shape)
    return k, float(s["min_dist"][k]), (int(a), int(b))


def fmt(x: Any, nd: int = 2) -> str:
    """A table cell: "–" for None, a float with ``nd`` decimals, anything else as text."""
    if x is None:
        return "–"
    if isinstance(x, float):
        return f"{x:.{nd}f}"
    return str(x)


FAILED_CELL_CHARS = 160  # a failed method's reason in a table cell is cut to this length


def failed_rows(failed: dict[str, str] | None, columns: int) -> str:
    """Table rows (markdown, ``columns`` cells) of methods whose run failed: the method,
    ``FAILED: <reason>`` (cut to :data:`FAILED_CELL_CHARS`, pipes escaped), "–" elsewhere."""
    rows = ""
    for m, why in (failed or {}).items():
        reason = why.splitlines()[0] if why else "no reason given"
        if len(reason) > FAILED_CELL_CHARS:
            reason = reason[:FAILED_CELL_CHARS - 1] + "…"
        reason = reason.replace("|", "\\|")
        rows += (f"| {LABELS.get(m, m)} | FAILED: {reason} |"
                 + " – |" * (columns - 2) + "\n")
    return rows
