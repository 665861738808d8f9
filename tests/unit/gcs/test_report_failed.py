"""The comparison report with a failed method (written with the others, the failed one
marked with its reason) and its plots' legibility: zoom legends off the curve's closest
point, energy labels apart, one number for a snapshot's title and legend."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from report_runs import D_SAFE, EDGES, ENERGY_U, FOLLOWERS, closing_series, three_methods

from gcs.report import animation, paths, plots
from gcs.report.comparison import compare_table, paper_differences, write_report
from gcs.report.safety_table import safety_table

WHY = ("the daemon of agent(s) 1 exited before the start: offboard: cannot open MAVLink "
       "udpin:127.0.0.1:14540: [Errno 98] Address already in use (log: x/offboard-1.log)")


def _metrics(min_d: float, eu: float) -> dict:
    return {"min_distance_m": min_d, "collisions": int(min_d < 0.3), "energy_u": eu,
            "energy_thrust": 1000.0 + eu, "energy_thrust_excess": eu / 2,
            "formation_time_s": 4.0, "qp_fallbacks": 0, "h_min": 0.1}


@pytest.fixture
def finished() -> tuple[dict, dict]:
    series = three_methods()
    metrics = {m: _metrics(float(s["min_dist"].min()), ENERGY_U[m]) for m, s in series.items()}
    return metrics, series


def _rows(table: str, label: str) -> list[list[str]]:
    return [[c.strip() for c in ln.strip("|").split(" | ")]
            for ln in table.splitlines() if ln.startswith(f"| {label} |")]


def test_tables_mark_the_failed_method_with_its_reason(finished: tuple[dict, dict]) -> None:
    metrics, _ = finished
    for table, ncols in ((compare_table(metrics, D_SAFE, {"dcbf": WHY}), 11),
                         (safety_table(metrics, {"dcbf": WHY}), 10)):
        head = table.splitlines()[0].strip("|").split(" | ")
        assert len(head) == ncols
        rows = _rows(table, "Sampled-data CBF (ours)")
        assert len(rows) == 1 and len(rows[0]) == ncols, rows
        assert rows[0][1].startswith("FAILED: the daemon of agent(s) 1 exited")
        assert rows[0][2:] == ["–"] * (ncols - 2)
        assert len(_rows(table, "Proposed RCBF")) == 1  # the finished ones stay
    # a reason with a pipe cannot break the table
    t = compare_table(metrics, D_SAFE, {"dcbf": "a | b"})
    assert "FAILED: a \\| b" in t


@pytest.fixture
def plot_calls(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, Any]]:
    """The plots write_report asks for (name, first argument), none drawn (seconds each)."""
    calls: list[tuple[str, Any]] = []
    for name in ("plot_min_distance", "plot_errors", "plot_snapshots", "plot_energy"):
        monkeypatch.setattr(plots, name,
                            lambda first, *a, _n=name, **k: calls.append((_n, first)))
    # the flown paths (what they mark, without drawing) and no animation
    monkeypatch.setattr(paths, "plot_paths", lambda s, *a, **k: paths.closest_of(s, a[3]))
    monkeypatch.setattr(animation, "animate_closest", lambda *a, **k: None)
    return calls


def test_report_is_written_with_the_methods_that_finished(
    finished: tuple[dict, dict], tmp_path: Path, plot_calls: list[tuple[str, Any]]
) -> None:
    metrics, series = finished
    path = write_report(tmp_path, "tiny", metrics, series, FOLLOWERS, EDGES, D_SAFE, ["g"],
                        tau_safe_s=0.8, deadline_s=3.0, failed={"dcbf": WHY})
    text = path.read_text()
    assert "**Failed runs.** 1 of the 4 methods did not finish" in text
    assert "of the 3 that did" in text
    assert f"* **Sampled-data CBF (ours)** (`dcbf`): {WHY}" in text
    assert text.count("| Sampled-data CBF (ours) | FAILED: ") == 2  # both tables
    # the energy paragraph counts the methods of its table, not those of the paper
    assert "for the 3 methods of the table" in text
    snaps = [first for name, first in plot_calls if name == "plot_snapshots"]
    assert [sn["t"] is series[m]["t"] for sn, m in zip(snaps, series, strict=True)] == [True] * 3
    energy = [first for name, first in plot_calls if name == "plot_energy"]
    assert energy == [metrics]  # the finished methods only
    assert "snapshots_dcbf" not in text and "(snapshots_rcbf.png)" in text


def test_method_count_follows_the_table() -> None:
    """Four methods, one (dcbf) not in the paper's table: the text says 4."""
    series = {m: closing_series(1.0 + k, 0.3 + 0.2 * k)
              for k, m in enumerate(("rcbf", "dcbf", "apf", "none"))}
    metrics = {m: _metrics(float(s["min_dist"].min()), 100.0 * (k + 1))
               for k, (m, s) in enumerate(series.items())}
    text = paper_differences(metrics, series, D_SAFE, FOLLOWERS)
    assert "for the 4 methods of the table" in text
    assert len(_rows(compare_table(metrics, D_SAFE), "Sampled-data CBF (ours)")) == 1


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Every figure the plots save, drawn (their layout final) before they are closed."""
    import matplotlib.figure

    saved: list[Any] = []
    real = matplotlib.figure.Figure.savefig

    def keep(self: Any, *a: Any, **k: Any) -> None:
        real(self, *a, **k)
        self.canvas.draw()
        saved.append(self)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return saved


@pytest.mark.full
def test_zoom_legend_leaves_the_closest_point_visible(
    finished: tuple[dict, dict], figures: list[Any], tmp_path: Path
) -> None:
    _, series = finished
    plots.plot_min_distance(series, D_SAFE, tmp_path / "m.png")
    (fig,) = figures
    zooms = fig.axes[1:]
    assert len(zooms) == len(series)
    for ax in zooms:
        box = ax.get_legend().get_window_extent()
        marker = next(ln for ln in ax.get_lines() if ln.get_marker() == "v")
        x, y = ax.transData.transform(np.column_stack(marker.get_data()))[0]
        assert not box.contains(x, y), ax.get_title()
        curve = ax.get_lines()[0]  # the zoomed curve: under the legend at most 20 % of it
        pts = ax.transData.transform(np.column_stack(curve.get_data()))
        assert np.mean([box.contains(px, py) for px, py in pts]) <= 0.2, ax.get_title()


def test_energy_labels_do_not_overlap(finished: tuple[dict, dict], figures: list[Any],
                                      tmp_path: Path) -> None:
    metrics = {**finished[0], "dcbf": _metrics(1.2, 150.0)}
    plots.plot_energy(metrics, tmp_path / "e.png")
    (fig,) = figures
    for ax in fig.axes:
        boxes = [t.get_window_extent() for t in ax.get_xticklabels() if t.get_text()]
        assert len(boxes) == 4
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                assert not boxes[i].overlaps(boxes[j]), (ax.get_title(), i, j)


@pytest.mark.full
def test_snapshot_title_and_legend_give_one_number(figures: list[Any], tmp_path: Path) -> None:
    s = closing_series(2.0, 0.3)
    # the recorded distance differs from the centre-to-centre distance of the positions
    # by 0.008 m (as the simulator's record can): both texts must still show one number
    s["min_dist"] = s["min_dist"] + 0.008
    times = plots.snapshot_times(s, 4.0)
    plots.plot_snapshots(s, EDGES, times, tmp_path / "s.png", "x", FOLLOWERS)
    (fig,) = figures
    closest = next(ax for ax in fig.axes if "closest" in ax.get_title())
    in_title = re.findall(r"at (\d+\.\d+) m", closest.get_title())
    in_legend = [re.findall(r"nearest pair (\d+\.\d+) m", t.get_text())
                 for t in closest.get_legend().get_texts()]
    assert in_title == [f"{float(s['min_dist'].min()):.2f}"]
    assert [x for xs in in_legend for x in xs] == in_title
