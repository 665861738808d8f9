"""The comparison report (gcs.report.comparison) on a tiny synthetic input: files, legends, text."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from report_runs import D_SAFE, EDGES, ENERGY_U, FOLLOWERS, three_methods

from gcs.report.comparison import (
    compare_legend,
    compare_table,
    paper_differences,
    write_report,
)
from gcs.report.plots import snapshot_times
from gcs.report.safety_table import safety_legend, safety_table
from gcs.report.shared import closest_approach
from gcs.report.sweep import seeds_legend, seeds_table


def _metrics(min_d: float, eu: float, formed: float | None) -> dict:
    return {
        "min_distance_m": min_d,
        "collisions": int(min_d < 0.3),
        "energy_u": eu,
        "energy_thrust": 1000.0 + eu,
        "energy_thrust_excess": eu / 2,
        "formation_time_s": formed,
        "tracking_rms_m": 0.02 if formed is not None else None,
        "tracking_max_m": 0.05 if formed is not None else None,
        "tracking_time_above_0p1_s": 0.0 if formed is not None else None,
        "h_min": 0.12 if min_d > 0.5 else -0.3,
        "barrier_violation_steps": 0 if min_d > 0.5 else 4,
        "barrier_violation_pair_steps": 0 if min_d > 0.5 else 5,
        "min_distance_by_phase_m": {"takeoff": None, "formation": 0.9 if min_d > 0.5 else min_d,
                                    "mission": 1.5, "landing": None},
        "input_clipped_steps": 7,
        "qp_fallbacks": 0,
    }


@pytest.fixture
def inputs() -> tuple[dict, dict]:
    series = three_methods()
    metrics = {
        m: _metrics(float(s["min_dist"].min()), ENERGY_U[m], 4.0 if m != "none" else None)
        for m, s in series.items()
    }
    return metrics, series


def _columns(table: str) -> list[str]:
    return [c.strip() for c in table.splitlines()[0].strip("|").split("|")]


def test_every_column_has_a_definition(inputs: tuple[dict, dict]) -> None:
    metrics, _ = inputs
    cols = _columns(compare_table(metrics, D_SAFE))
    defined = re.findall(r"^\* \*\*(.+?)\*\*: ", compare_legend(D_SAFE), flags=re.M)
    assert cols == defined
    assert all("(" in c for c in cols if c.startswith(("Ours", "Paper min", "∫", "Formed")))
    cols = _columns(safety_table(metrics))
    defined = re.findall(r"^\* \*\*(.+?)\*\*: ", safety_legend(D_SAFE, 0.8, 20.0), flags=re.M)
    assert cols == defined
    runs = {m: [metrics[m], metrics[m]] for m in metrics}
    cols = _columns(seeds_table(runs, D_SAFE))
    defined = re.findall(r"^\* \*\*(.+?)\*\*: ", seeds_legend(D_SAFE), flags=re.M)
    assert cols[1:] == defined  # "Method" is the same column as in the first table


def test_closest_approach_and_snapshot_times(inputs: tuple[dict, dict]) -> None:
    _, series = inputs
    k, d, pair = closest_approach(series["apf"])
    assert series["apf"]["t"][k] == pytest.approx(1.5)
    assert d == pytest.approx(0.2) and pair == (2, 3)
    times = snapshot_times(series["apf"], 4.0)
    assert [round(t, 3) for t, _ in times] == [0.0, 1.5, 4.0, 5.9]
    assert "closest" in times[1][1] and times[2][1] == "formed"
    assert len(snapshot_times(series["none"], None)) == 3  # never formed: no such snapshot


def test_paper_paragraph_uses_the_run(inputs: tuple[dict, dict]) -> None:
    metrics, series = inputs
    text = paper_differences(metrics, series, D_SAFE, FOLLOWERS)
    assert "4.0 m edges" in text  # the leaders' separation in the synthetic run
    assert "over by t = 1.6 s" in text  # last sample below D_safe (APF's dip)
    assert "kept by Proposed RCBF; crossed by Improved APF, No collision avoidance" in text
    assert "the same ordering as the paper" in text
    assert "docs/paper-departures.md" in text
    metrics["apf"]["energy_u"] = 100.0
    assert "a different ordering from the paper" in paper_differences(
        metrics, series, D_SAFE, FOLLOWERS
    )


@pytest.mark.full
@pytest.mark.slow  # the GIF and every figure: started first, not left to the end
def test_write_report_writes_markdown_and_plots(inputs: tuple[dict, dict], tmp_path: Path) -> None:
    metrics, series = inputs
    seeds = {m: [metrics[m]] * 3 for m in metrics}
    path = write_report(
        tmp_path, "tiny", metrics, series, FOLLOWERS, EDGES, D_SAFE, ["gain line"], seeds,
        tau_safe_s=0.8, deadline_s=3.0,
    )
    text = path.read_text()
    assert "* **∫Σ‖u‖²dt (m²/s³)**:" in text and "* **Runs < D_safe**:" in text
    assert "### How these numbers differ from the paper's Table 3" in text
    assert "## Safety and tracking (true states)" in text and "* **True h_min (m²)**:" in text
    assert ("| Proposed RCBF | – (–) | 0.120 | – | 0 | 0 | 0.900 / 1.500 | 7 | 0.020 / 0.050 "
            "| 0.00 |") in text
    for name in ("min_distance", "errors", "energy", *(f"snapshots_{m}" for m in series)):
        png = tmp_path / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"({name}.png)" in text
