"""gcs.mission.sweep input parsing and gcs.report.sweep statistics (pure functions)."""

from __future__ import annotations

import pytest
from scipy.stats import binom

from gcs.mission.sweep import (
    SweepInputError,
    parse_duration,
    parse_jobs,
    parse_methods,
    parse_seeds,
)
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
)


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
