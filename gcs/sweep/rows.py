"""Bookkeeping of ``gcs mission sweep`` shared by the local pool and the Dask cluster
(:mod:`gcs.sweep`, :mod:`gcs.sweep.cluster`): the progress line (runs done,
failed, wall time left), ``runs.csv`` streamed as the runs end (:class:`RowSink`) and the rows
an earlier sweep left for ``--resume`` (:func:`resumable_rows`)."""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any, TextIO

from gcs.mission.progress import Progress
from gcs.report.sweep import CSV_COLUMNS, ID_COLUMNS, csv_cells

_TEXT_COLUMNS = frozenset({"scenario", "method", "status", "error", "safety_verdict"})


def _cell_value(key: str, cell: str) -> Any:
    """The value :func:`gcs.report.sweep.write_csv` wrote as ``cell``: empty → None,
    True/False, int, float; the text columns stay text."""
    if key in _TEXT_COLUMNS:
        return cell
    if cell == "":
        return None
    if cell in ("True", "False"):
        return cell == "True"
    for kind in (int, float):
        try:
            return kind(cell)
        except ValueError:
            pass
    return cell


def read_csv_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a ``runs.csv`` with their values typed back (:func:`_cell_value`), so
    that writing them again gives the same cells."""
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or not set(ID_COLUMNS) <= set(reader.fieldnames):
            raise ValueError(f"{path}: not a runs.csv (columns {', '.join(ID_COLUMNS)})")
        return [{k: _cell_value(k, v or "") for k, v in r.items() if k is not None}
                for r in reader]


def _eta(seconds: float | None) -> str:
    if seconds is None:
        return "? left"
    s = int(round(seconds))
    if s < 60:
        return f"{s} s left"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s left"
    return f"{s // 3600} h {s % 3600 // 60:02d} min left"


class SweepProgress:
    """The sweep's bar (:class:`~gcs.mission.progress.Progress` over the simulated seconds of
    all runs) with the runs done, the failed ones and the estimated wall time left: the wall
    time so far times the simulated seconds still to run over those done."""

    def __init__(self, durations_s: list[float], show: bool = True,
                 clock: Callable[[], float] = time.monotonic,
                 stream: TextIO | None = None) -> None:
        self.total_s = float(sum(durations_s))
        self.n = len(durations_s)
        self.done = self.failed = 0
        self.done_s = 0.0
        self.clock = clock
        self.t0 = clock()
        self.bar = Progress(self.total_s, label=f"sweep {self.n} runs", stream=stream,
                            clock=clock) if show else None

    def eta_s(self) -> float | None:
        """Estimated wall seconds left; None before the first run ends."""
        if self.done_s <= 0:
            return None
        return (self.clock() - self.t0) * (self.total_s - self.done_s) / self.done_s

    def add(self, duration_s: float, ok: bool) -> None:
        """A run of ``duration_s`` simulated seconds ended (``ok``: status ok)."""
        self.done += 1
        self.failed += not ok
        self.done_s += duration_s
        if self.bar is not None:
            self.bar.update(self.done_s, f"{self.done}/{self.n} runs, {self.failed} failed, "
                                         f"{_eta(self.eta_s())}")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def row_key(row: dict[str, Any]) -> tuple[str, str, int]:
    return (str(row["scenario"]), str(row["method"]), int(row["seed"]))


class RowSink:
    """``runs.csv`` written as the runs end: the ``kept`` rows first, then each new row
    appended and flushed at once, so a sweep stopped at any moment (even SIGKILL) leaves
    every finished run on disk for ``--resume``. A row whose (scenario, method, seed) is
    already there is dropped (never counted twice)."""

    def __init__(self, path: Path, kept: list[dict[str, Any]]) -> None:
        self.rows: list[dict[str, Any]] = []
        self.keys: set[tuple[str, str, int]] = set()
        self._fh: IO[str] = path.open("w", newline="")
        self._w = csv.DictWriter(self._fh, fieldnames=list(CSV_COLUMNS), extrasaction="ignore")
        self._w.writeheader()
        for r in kept:
            self.add(r)

    def add(self, row: dict[str, Any]) -> bool:
        """Append ``row``; False (nothing written) when its key is already there."""
        key = row_key(row)
        if key in self.keys:
            return False
        self.keys.add(key)
        self.rows.append(row)
        self._w.writerow(csv_cells(row))
        self._fh.flush()
        return True

    def close(self) -> None:
        self._fh.close()


def resumable_rows(
    path: Path, grid: dict[tuple[str, str, int], float] | None = None,
) -> list[dict[str, Any]]:
    """The ``ok`` rows of an earlier sweep's ``runs.csv`` (none when it is missing); a
    crashed run is run again. ``grid``: the runs of this sweep, (scenario, method, seed)
    to their simulated seconds. A row that is not one of them, or that ran another
    duration, is refused (ValueError, nothing kept): the file is the record of one sweep,
    and resuming with another grid would mix two sweeps in one summary, or drop the rows
    that are not in the new grid when the file is written again."""
    if not path.exists():
        return []
    try:
        rows = read_csv_rows(path)
    except (OSError, ValueError, KeyError) as exc:
        raise ValueError(f"--resume: cannot read {path} ({exc})") from None
    if grid is not None:
        foreign = [r for r in rows if grid.get(row_key(r)) != r["duration_s"]]
        if foreign:
            r = foreign[0]
            what = ("ran for another duration" if row_key(r) in grid
                    else "is not in this sweep's grid")
            raise ValueError(
                f"--resume: {path} holds {len(foreign)} run(s) this sweep would not make "
                f"(scenario {r['scenario']!r}, method {r['method']!r}, seed {r['seed']}, "
                f"{r['duration_s']} s {what}); resume with the scenarios, methods, seeds "
                "and duration that made them, or choose another --out")
    return [r for r in rows if r["status"] == "ok"]
