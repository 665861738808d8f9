"""A run's series with what the safety filter did at each step (docs/records.md):
:class:`RunSeries`, the :class:`~gcs.report.metrics.Series` every runner records, plus per
agent and step the QP's status, its active rows, its slacks, the nominal control u_nom
and the filter's correction ‖u − u_nom‖. ``series.npz`` holds these arrays beside the
others; a file written before them has none (:func:`filter_arrays` then gives the
"unknown" values of :func:`unknown_filter`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TypeVar

import numpy as np

from gcs.report.metrics import Series
from swarm_common.enums import QPStatus

# the record's uint8 code of each QP status (its index here); UNKNOWN_STATUS: no status
# (a leader's step has INACTIVE: no filter)
QP_STATUS_CODES: tuple[QPStatus, ...] = (
    QPStatus.INACTIVE, QPStatus.SOLVED, QPStatus.RELAXED, QPStatus.FALLBACK)
STATUS_CODE: dict[str, int] = {str(s): c for c, s in enumerate(QP_STATUS_CODES)}
UNKNOWN_STATUS = 255
MAX_COUNT = 255  # the active rows' count saturates there (uint8)


@dataclass
class RunSeries(Series):
    """:class:`~gcs.report.metrics.Series` and the safety filter's report, (K,N) each
    unless said (scenario order); in a recorded run float32 values as they crossed the
    wire."""

    qp_status: np.ndarray  # uint8: QP_STATUS_CODES index, UNKNOWN_STATUS where none came
    qp_active: np.ndarray  # uint8: rows active at the QP's solution (offboard.records.ActiveRows)
    qp_kinds: np.ndarray  # uint8: their kinds, swarm_common.enums.QPRow bits
    clf_slack: np.ndarray  # the CLF row's slack δ (m/s²)
    qp_relax: np.ndarray  # the barrier rows' relaxation σ (m/s²)
    u_nom: np.ndarray  # (K,N,3) nominal control before the filter (m/s², ENU)
    u_corr: np.ndarray  # the filter's correction ‖u_f − u_nom‖ (m/s², AgentStatus.correction)


FILTER_FIELDS: tuple[str, ...] = tuple(
    f.name for f in fields(RunSeries) if f.name not in Series.__dataclass_fields__)


def unknown_filter(k: int, n: int, fill: float = np.nan) -> dict[str, np.ndarray]:
    """The filter arrays of ``k`` steps of ``n`` agents with nothing known: status
    UNKNOWN_STATUS, no active rows, the floats ``fill``."""
    return {"qp_status": np.full((k, n), UNKNOWN_STATUS, np.uint8),
            "qp_active": np.zeros((k, n), np.uint8), "qp_kinds": np.zeros((k, n), np.uint8),
            "clf_slack": np.full((k, n), fill), "qp_relax": np.full((k, n), fill),
            "u_nom": np.full((k, n, 3), fill), "u_corr": np.full((k, n), fill)}


def filter_arrays(s: Series) -> dict[str, np.ndarray]:
    """``s``'s filter arrays by name (:data:`FILTER_FIELDS`), or the unknown ones of
    :func:`unknown_filter` for a series that has none."""
    if isinstance(s, RunSeries):
        return {f: getattr(s, f) for f in FILTER_FIELDS}
    return unknown_filter(*np.shape(s.p)[:2])


def run_series(s: Series, filt: Mapping[str, np.ndarray] | None = None) -> RunSeries:
    """``s`` with the filter arrays ``filt`` (default: ``s``'s own, else unknown)."""
    base = {f: getattr(s, f) for f in Series.__dataclass_fields__}
    return RunSeries(**base, **(filter_arrays(s) if filt is None else dict(filt)))


S = TypeVar("S", bound=Series)


def rows_of(s: S, rows: slice | np.ndarray) -> S:
    """The series of ``s``'s ``rows`` (copies), of ``s``'s own class."""
    return type(s)(**{f: np.array(v[rows]) for f, v in s.as_dict().items()})
