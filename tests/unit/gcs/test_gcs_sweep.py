"""gcs.sweep input parsing, gcs.report.sweep statistics and runs.csv bookkeeping
(gcs.sweep.rows)."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binom

from gcs.report.metrics import METRIC_KEYS
from gcs.report.sweep import (
    CSV_COLUMNS,
    clopper_pearson_lower,
    clopper_pearson_upper,
    flat_row,
    group_stats,
    rates_table,
    run_rates,
    summary_table,
    wilson_interval,
    write_csv,
)
from gcs.sweep.jobs import (
    SweepInputError,
    load_all,
    parse_address,
    parse_duration,
    parse_jobs,
    parse_methods,
    parse_seeds,
    scenario_from_text,
)
from gcs.sweep.rows import RowSink, SweepProgress, read_csv_rows, resumable_rows
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]


def test_parse_seeds_range_and_list() -> None:
    assert parse_seeds("1-5") == [1, 2, 3, 4, 5]
    assert parse_seeds("1,4,9") == [1, 4, 9]
    assert parse_seeds("7") == [7]
    assert parse_seeds("3,3,1") == [3, 1]
    for bad in ("5-1", "-3", "", "1-", "a", "1,,2", "1-2-3", "1,-2"):
        with pytest.raises(SweepInputError):
            parse_seeds(bad)


def test_parse_methods_jobs_duration() -> None:
    assert parse_methods("rcbf,apf,none") == ["rcbf", "apf", "none"]
    with pytest.raises(SweepInputError, match="magic"):
        parse_methods("rcbf,magic")
    with pytest.raises(SweepInputError):
        parse_methods(",")
    assert parse_jobs("3") == 3 and parse_jobs(None) >= 1
    for bad in ("0", "-1", "x"):
        with pytest.raises(SweepInputError):
            parse_jobs(bad)
    assert parse_duration(None) is None and parse_duration("2.5") == 2.5
    for bad in ("0", "-1", "nan", "inf", "x"):
        with pytest.raises(SweepInputError):
            parse_duration(bad)


def test_clopper_pearson_upper() -> None:
    for n in (1, 20, 100):
        assert clopper_pearson_upper(0, n) == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-9)
    assert clopper_pearson_upper(0, 100) == pytest.approx(0.0295, abs=1e-4)  # ≈ 3/n
    ub = clopper_pearson_upper(3, 20)
    assert binom.cdf(3, 20, ub) == pytest.approx(0.05, abs=1e-9)  # exact definition
    assert clopper_pearson_upper(20, 20) == 1.0 and clopper_pearson_upper(0, 0) == 1.0


def _row(method: str, seed: int, md: float, h: float, viol: int, coll: int) -> dict:
    return {"scenario": "s", "method": method, "seed": seed, "status": "ok", "error": "",
            "min_distance_m": md, "h_min": h, "barrier_violation_steps": viol,
            "collisions": coll}


def test_group_stats_and_table_count_crashes_apart() -> None:
    rows = [_row("rcbf", s, 0.8 + s / 50, 0.1, 0, 0) for s in range(10)]
    rows.append({"scenario": "s", "method": "rcbf", "seed": 99, "status": "crashed",
                 "error": "RuntimeError: boom"})
    rows += [_row("none", s, 0.05, -8.0, 40, 2) for s in range(10)]
    g = group_stats([r for r in rows if r["method"] == "rcbf"])
    assert g["runs"] == 10 and g["crashed"] == 1 and g["violation_runs"] == 0
    assert g["violation_p_upper"] == pytest.approx(1 - 0.05 ** 0.1)
    table = summary_table(rows, ["rcbf", "none"])
    assert "| s | rcbf | 10 (1) | 0.800 / 0.809 / 0.890 |" in table
    assert "| 10/10 | 400 | 10/10 (20) | 1.000 | 1.000 | 0 | 0 | 0/10 |" in table


def test_flat_row_covers_every_metric_column() -> None:
    m: dict[str, object] = {k: 1.0 for k in METRIC_KEYS}
    m["min_distance_by_phase_m"] = {"takeoff": None, "formation": 0.7, "mission": 2.0,
                                    "landing": None}
    row = flat_row(m)
    assert set(row) == set(CSV_COLUMNS) - {"scenario", "method", "seed", "status", "error",
                                           "duration_s"}
    assert row["min_distance_formation_m"] == 0.7 and row["min_distance_takeoff_m"] is None


def test_rates_count_verdicts_success_and_stalls() -> None:
    """Safe: verdict not unsafe; success: formed, or the mission completed when there is
    one; alarmed: verdict not safe; stalled: a deadlock event. The list of events is a
    metrics.json field, never a CSV column."""
    rows = [
        {"status": "ok", "safety_verdict": "safe", "formation_time_s": 6.0,
         "mission_completed": None, "deadlock_events": 0},
        {"status": "ok", "safety_verdict": "alarm", "formation_time_s": None,
         "mission_completed": True, "deadlock_events": 2},
        {"status": "ok", "safety_verdict": "unsafe", "formation_time_s": 9.0,
         "mission_completed": False, "deadlock_events": 0},
    ]
    assert run_rates(rows) == (2, 2, 2, 1)
    table = rates_table([{**r, "scenario": "s", "method": "dcbf"} for r in rows], ["dcbf"])
    assert "| s | dcbf | 3 | 2/3 (" in table and "| 1/3 |" in table
    assert "safety_alarms" not in CSV_COLUMNS and "safety_verdict" in CSV_COLUMNS
    assert 0.0 < clopper_pearson_lower(99, 100) < 0.99 < clopper_pearson_upper(99, 100)


@pytest.mark.parametrize(("x", "n"), [(0, 10), (3, 20), (20, 20), (57, 100), (1, 1)])
def test_wilson_interval_inverts_the_score_test(x: int, n: int) -> None:
    """The interval is the set of p that the score test |x/n − p| ≤ z √(p(1−p)/n) keeps:
    found here by dense sampling of p (step 1e-6, so agreement to 2e-6)."""
    lo, hi = wilson_interval(x, n)
    p = np.linspace(0.0, 1.0, 1_000_001)
    kept = p[np.abs(x / n - p) <= 1.959963984540054 * np.sqrt(p * (1 - p) / n)]
    assert lo == pytest.approx(kept.min(), abs=2e-6) and hi == pytest.approx(kept.max(), abs=2e-6)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_wilson_interval_known_value() -> None:
    # 0 of 10: the published 95 % Wilson upper bound 0.2775 (z²/(n + z²))
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.27753, abs=1e-5)


def test_rates_table_has_wilson_columns() -> None:
    rows = [{"scenario": "s", "method": "rcbf", "status": "ok", "safety_verdict": "safe",
             "formation_time_s": 5.0, "mission_completed": None, "deadlock_events": 0}] * 10
    table = rates_table(rows, ["rcbf"])
    assert "Safe 95 % CI" in table.splitlines()[0]
    # 10/10 safe: [1 − 0.2775, 1]; 0/10 alarmed: [0, 0.2775]
    assert "| 0.722–1.000 | 0.722–1.000 | 0.000–0.278 |" in table


def _csv_row(seed: int, **kw: object) -> dict[str, object]:
    row: dict[str, object] = {c: None for c in CSV_COLUMNS}
    row.update({"scenario": "cube8", "method": "rcbf", "seed": seed, "status": "ok",
                "error": "", "duration_s": 2.0, "min_distance_m": 0.8125, "collisions": 0,
                "safety_verdict": "safe", "mission_completed": False})
    row.update(kw)
    return row


def test_runs_csv_reads_back_to_the_same_cells(tmp_path: Path) -> None:
    rows = [_csv_row(2, h_min=-0.25), _csv_row(1, status="crashed", error="ValueError: 3, 4")]
    write_csv(tmp_path / "a.csv", rows)
    back = read_csv_rows(tmp_path / "a.csv")
    assert [r["seed"] for r in back] == [1, 2]  # sorted by (scenario, method, seed)
    assert back[1]["h_min"] == -0.25 and back[1]["collisions"] == 0
    assert back[1]["mission_completed"] is False and back[1]["formation_time_s"] is None
    assert back[0]["error"] == "ValueError: 3, 4" and back[1]["error"] == ""
    write_csv(tmp_path / "b.csv", back)
    assert (tmp_path / "b.csv").read_bytes() == (tmp_path / "a.csv").read_bytes()
    assert [r["seed"] for r in resumable_rows(tmp_path / "a.csv")] == [2]  # crashed: re-run
    assert resumable_rows(tmp_path / "missing.csv") == []


def test_resume_refuses_rows_of_another_grid(tmp_path: Path) -> None:
    """--resume keeps the rows of the sweep's own grid only: a row of another scenario,
    method or seed, or of another duration, is refused in one line naming it (the file
    is left as it is), and a grid that holds every row resumes."""
    path = tmp_path / "runs.csv"
    write_csv(path, [_csv_row(1), _csv_row(2, status="crashed", error="E"), _csv_row(3)])
    before = path.read_bytes()
    grid = {("cube8", "rcbf", s): 2.0 for s in (1, 2, 3, 4)}
    assert [r["seed"] for r in resumable_rows(path, grid)] == [1, 3]
    for other, why in (({k: v for k, v in grid.items() if k[2] != 2}, "not in this sweep"),
                       ({k: 3.0 for k in grid}, "another duration"),
                       ({("cube8", "dcbf", s): 2.0 for s in (1, 2, 3)}, "not in this sweep")):
        with pytest.raises(ValueError, match=why) as err:
            resumable_rows(path, other)
        assert "\n" not in str(err.value) and "--out" in str(err.value)
    assert path.read_bytes() == before


def test_row_sink_appends_flushed_rows_once(tmp_path: Path) -> None:
    path = tmp_path / "runs.csv"
    sink = RowSink(path, [_csv_row(1)])
    assert sink.add(_csv_row(2)) is True
    assert sink.add(_csv_row(2, min_distance_m=9.0)) is False  # the same run again: dropped
    assert [r["seed"] for r in read_csv_rows(path)] == [1, 2]  # on disk before close
    sink.close()
    assert read_csv_rows(path)[1]["min_distance_m"] == 0.8125 and len(sink.rows) == 2


def test_sweep_progress_counts_failed_runs_and_time_left() -> None:
    now = [100.0]
    out = io.StringIO()
    bar = SweepProgress([2.0, 2.0, 4.0], clock=lambda: now[0], stream=out)
    assert bar.eta_s() is None
    now[0] = 110.0
    bar.add(2.0, ok=True)  # 2 of 8 simulated s in 10 s wall: 6 s more take 30 s
    assert bar.eta_s() == pytest.approx(30.0, abs=1e-9)
    now[0] = 130.0
    bar.add(4.0, ok=False)  # 6 of 8 in 30 s: 2 s more take 10 s
    assert bar.eta_s() == pytest.approx(10.0, abs=1e-9)
    assert "2/3 runs, 1 failed, 10 s left" in out.getvalue()


def test_parse_address() -> None:
    assert parse_address("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert parse_address("tls://sched.example.org:8786") == "tls://sched.example.org:8786"
    for bad in ("10.0.0.5:8786", "tcp://host", "tcp://host:0", "tcp://host:70000",
                "http://host:8786", "tcp://a b:1"):
        with pytest.raises(SweepInputError, match="--cluster"):
            parse_address(bad)


def test_scenario_from_text_is_the_file_scenario() -> None:
    path = str(ROOT / "scenarios" / "cube8.toml")
    text = Path(path).read_text()
    assert scenario_from_text(text, path).to_toml_dict() == load_scenario(path).to_toml_dict()
    assert scenario_from_text(text, path).path == load_scenario(path).path


@pytest.mark.full
def test_local_sweep_does_not_import_dask() -> None:
    code = ("import sys, gcs.cli, gcs.sweep.cli, gcs.sweep.local; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'dask', 'distributed'}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stderr


def test_two_files_of_one_scenario_name_are_refused(tmp_path: Path) -> None:
    """runs.csv keys a run by scenario name: a second file of the same name (or the same
    file twice) would be run and its rows dropped, so the sweep refuses it in one line
    naming both files; files of their own names load."""
    cube8 = (ROOT / "scenarios" / "cube8.toml").read_text()
    a, b, c = tmp_path / "a.toml", tmp_path / "b.toml", tmp_path / "c.toml"
    a.write_text(cube8)
    b.write_text(cube8.replace("seed = 1\n", "seed = 77\n", 1))
    c.write_text(cube8.replace('name = "cube8"', 'name = "cube8_other"', 1))
    assert "seed = 77" in b.read_text() and 'name = "cube8_other"' in c.read_text()
    for paths, first in (([a, b], a), ([a, a], a)):
        with pytest.raises(SweepInputError, match=rf"{paths[1]}: scenario.name = 'cube8', "
                           rf"as {first}: a sweep keys its runs by scenario name") as err:
            load_all([str(p) for p in paths])
        assert "\n" not in str(err.value)
    assert [sc.name for _, _, sc in load_all([str(a), str(c)])] == ["cube8", "cube8_other"]
