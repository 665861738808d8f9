"""Load a run for export and write its CSV files (``gcs log export``, docs/records.md).

A run is a run folder (``metrics.json`` + ``series.npz``, :mod:`gcs.mission.run_output`)
or a ``record.mcap`` (:mod:`gcs.records.reader`). CSV: one ``vehicle_<id>.csv`` per
vehicle, one row per control step, the unit in each column's name (as QGroundControl's
CSV logs), and ``pairs.csv`` (one row per pair and step: distance and barrier h).
Numbers are written with 17 significant digits: a CSV reads back to the same doubles.
Every failure to load is a :class:`~gcs.records.reader.RecordError` (one line).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from gcs.records.pair_table import PairTable
from gcs.records.reader import RecordError, read_arrays
from gcs.records.series import RunSeries, filter_arrays, unknown_filter
from gcs.report.metrics import Series

MAX_METRICS_BYTES = 64 << 20  # a metrics.json read back (as swarm_common.inputs)
XYZ = ("x", "y", "z")
# (Series field, CSV column names) of a vehicle file, in order
VEHICLE_COLUMNS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("p", tuple(f"{a}_m" for a in XYZ)),
    ("v", tuple(f"v{a}_m_s" for a in XYZ)),
    ("p_des", tuple(f"{a}_des_m" for a in XYZ)),
    ("v_des", tuple(f"v{a}_des_m_s" for a in XYZ)),
    ("z1", tuple(f"{a}_est_m" for a in XYZ)),
    ("z2", tuple(f"v{a}_est_m_s" for a in XYZ)),
    ("xi_p", tuple(f"{a}_des_est_m" for a in XYZ)),
    ("lumped_est", tuple(f"d{a}_est_m_s2" for a in XYZ)),
    ("lumped_true", tuple(f"d{a}_true_m_s2" for a in XYZ)),
    ("u", tuple(f"u{a}_m_s2" for a in XYZ)),
    ("thrust", ("thrust_n",)),
    ("tilt_deg", ("tilt_deg",)),
    ("h_min", ("h_min_m2",)),
    ("solve_us", ("solve_us",)),
    ("fallback", ("qp_degraded",)),
    ("input_clipped", ("input_clipped",)),
    ("alarms", ("alarms",)),
    ("qp_status", ("qp_status",)),
    ("qp_active", ("active_rows",)),
    ("qp_kinds", ("active_kinds",)),
    ("clf_slack", ("clf_slack_m_s2",)),
    ("qp_relax", ("relax_m_s2",)),
    ("u_nom", tuple(f"u{a}_nom_m_s2" for a in XYZ)),
    ("u_corr", ("correction_m_s2",)),
)
PAIRS_HEADER = ("t_s", "i", "j", "distance_m", "h_m2")
# record field -> Series field (estimate and qp topics)
_FROM_ESTIMATE = {"p_m": "p", "v_m_s": "v", "p_des_m": "p_des", "v_des_m_s": "v_des",
                  "p_est_m": "z1", "v_est_m_s": "z2", "p_des_est_m": "xi_p",
                  "d_est_m_s2": "lumped_est", "d_true_m_s2": "lumped_true"}
_FROM_QP = {"u_m_s2": "u", "thrust_n": "thrust", "tilt_deg": "tilt_deg",
            "h_min_m2": "h_min", "solve_us": "solve_us", "degraded": "fallback",
            "input_clipped": "input_clipped", "alarms": "alarms", "u_nom_m_s2": "u_nom",
            "correction_m_s2": "u_corr", "clf_slack_m_s2": "clf_slack",
            "relax_m_s2": "qp_relax", "qp_status": "qp_status", "active_rows": "qp_active",
            "active_kinds": "qp_kinds"}
_SERIES = tuple(f.name for f in fields(RunSeries))
_OPTIONAL = {"alarms": np.uint8, "xi_p": float}  # older series.npz files lack them


def load_run_folder(run: Path) -> tuple[dict[str, Any], RunSeries]:
    """(``metrics.json`` document, series) of run folder ``run``; ``RecordError``."""
    if not run.is_dir():
        raise RecordError(f"{run}: not a run folder")
    mj, sz = run / "metrics.json", run / "series.npz"
    for f in (mj, sz):
        if not f.is_file():
            raise RecordError(f"{run}: not a run folder (no {f.name})")
    if mj.stat().st_size > MAX_METRICS_BYTES:
        raise RecordError(f"{mj}: larger than {MAX_METRICS_BYTES >> 20} MiB")
    try:
        doc = json.loads(mj.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise RecordError(f"{mj}: not JSON ({type(exc).__name__})") from None
    if not isinstance(doc, dict):
        raise RecordError(f"{mj}: not a run document (not a JSON object)")
    try:
        with np.load(sz, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in z.files}
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        msg = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise RecordError(f"{sz}: not a readable series ({msg})") from None
    return doc, series_from_arrays(sz, arrays)


def series_from_arrays(src: Path, arrays: dict[str, np.ndarray]) -> RunSeries:
    """A :class:`~gcs.records.series.RunSeries` of ``arrays`` checked for every field and
    a consistent shape (the filter's report unknown where the file has none)."""
    t, p = arrays.get("t"), arrays.get("p")
    if t is None or p is None or t.ndim != 1 or p.ndim != 3 or p.shape[::2] != (len(t), 3):
        raise RecordError(f"{src}: not a run series (no t (K,) and p (K,N,3))")
    k, n = p.shape[:2]
    out: dict[str, np.ndarray] = {}
    unknown = unknown_filter(k, n)
    for name in _SERIES:
        a = arrays.get(name, unknown.get(name))
        if a is None and name in _OPTIONAL:
            a = np.zeros((k, n, 3)) * np.nan if name == "xi_p" else np.zeros((k, n), np.uint8)
        if a is None:
            raise RecordError(f"{src}: not a run series (no {name})")
        if a.shape[:1] != (k,) or (a.ndim > 1 and a.shape[1] != n):
            raise RecordError(f"{src}: {name} has shape {a.shape}, not ({k}, {n}, ...)")
        out[name] = a
    return RunSeries(**out)


def load_record(path: Path) -> tuple[list[int], RunSeries, PairTable]:
    """(ids, series, the recorded pairs: their columns, distances (m) and barriers (m²))
    of a record file."""
    r = read_arrays(path)
    est, qp = [r.estimate[i] for i in r.ids], [r.qp[i] for i in r.ids]
    k = len(r.pairs)
    if any(len(a) != k for a in est + qp):
        raise RecordError(f"{path}: the topics hold different numbers of steps")
    vals: dict[str, np.ndarray] = {"t": np.asarray(r.pairs["t_s"], float),
                                   "min_dist": np.asarray(r.pairs["min_distance_m"], float)}
    vals.update(unknown_filter(k, len(r.ids)))  # an older record has no filter's report
    for src, table in ((est, _FROM_ESTIMATE), (qp, _FROM_QP)):
        for f, name in table.items():
            if f in (src[0].dtype.names or ()):
                vals[name] = np.stack([a[f] for a in src], axis=1)
    vals["fallback"] = vals["fallback"].astype(bool)
    vals["input_clipped"] = vals["input_clipped"].astype(bool)
    return r.ids, RunSeries(**vals), PairTable(
        _columns(path, r.ids, r.pairs["i"]), _columns(path, r.ids, r.pairs["j"]),
        np.asarray(r.pairs["distance_m"]), np.asarray(r.pairs["h_m2"]),
        np.asarray(r.pairs["min_h_m2"], float))


def _columns(path: Path, ids: list[int], pair_ids: np.ndarray) -> np.ndarray:
    """The agent columns of a record's pair ids (K, P), refused unless each is an agent's."""
    known = np.asarray(ids, np.int64)
    pid = np.asarray(pair_ids, np.int64)
    col = np.minimum(np.searchsorted(known, pid), max(len(known) - 1, 0))
    if pid.size and (not len(known) or not np.array_equal(known[col], pid)):
        raise RecordError(f"{path}: /pairs names an agent that has no topics")
    return col


def vehicle_table(s: Series, a: int) -> tuple[list[str], np.ndarray]:
    """(header, (K, C) values) of vehicle column ``a``."""
    head, cols = ["t_s"], [np.asarray(s.t, float)[:, None]]
    vals = {**filter_arrays(s), **s.as_dict()}
    for name, names in VEHICLE_COLUMNS:
        x = np.asarray(vals[name])[:, a]
        cols.append(x.reshape(len(x), -1).astype(float))
        head.extend(names)
    return head, np.hstack(cols)


def write_csv(out: Path, ids: list[int], s: Series, pairs: PairTable) -> list[Path]:
    """Write ``vehicle_<id>.csv`` for each agent and ``pairs.csv`` into ``out`` (created):
    one row per recorded pair (:mod:`gcs.records.pair_table`) and step. Returns the files."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for a, i in enumerate(ids):
        head, table = vehicle_table(s, a)
        f = out / f"vehicle_{i}.csv"
        np.savetxt(f, table, fmt="%.17g", delimiter=",", header=",".join(head), comments="")
        files.append(f)
    k, npair = pairs.distance_m.shape
    idv = np.asarray(ids)
    rows = np.column_stack([np.repeat(s.t, npair), idv[pairs.i].reshape(-1),
                            idv[pairs.j].reshape(-1), pairs.distance_m.reshape(-1),
                            pairs.h_m2.reshape(-1)])
    f = out / "pairs.csv"
    np.savetxt(f, rows, fmt=["%.17g", "%d", "%d", "%.17g", "%.17g"], delimiter=",",
               header=",".join(PAIRS_HEADER), comments="")
    files.append(f)
    return files


def read_vehicle_csv(path: Path) -> dict[str, np.ndarray]:
    """A ``vehicle_<id>.csv`` back as column name -> (K,) values."""
    head = path.read_text().split("\n", 1)[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, c] for c, name in enumerate(head)}
