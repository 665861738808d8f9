"""The report's flown-path figures and closest-approach animation (gcs.report.paths,
gcs.report.animation, gcs.report.figures) on a small synthetic run: the closest approach
they mark is the series' smallest distance and its time, every axis of every figure is
labelled with its unit, each figure names its time window and where it is in the record,
and the GIF is written only where matplotlib has its writer."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import matplotlib.animation
import numpy as np
import pytest
from conftest import ROOT
from PIL import Image

from gcs.report import animation, paths, plots
from gcs.report.comparison import write_report
from swarm_common.world.config import Geofence, Obstacle, ObstacleKind, make_world, polygon_fence

FOLLOWERS = [2, 3]
EDGES = [(0, 1), (0, 2), (1, 3), (2, 3)]
IDS = [11, 12, 13, 14]  # scenario ids that are not the columns + 1
DT = 0.1


def _series(dip_t: float = 2.5, dip_d: float = 0.4, n: int = 60) -> dict[str, np.ndarray]:
    """4 vehicles: leaders 0, 1 flying east at 0.5 m/s; followers 2, 3 climbing, closing to
    ``dip_d`` m at ``dip_t`` s. ``min_dist`` is 0.01 m below the centres' distance, as the
    physics-rate minimum can be: the figures must show the recorded number."""
    t = np.arange(n) * DT
    p = np.zeros((n, 4, 3))
    p[:, 0] = np.stack([0.5 * t, np.zeros(n), np.full(n, 5.0)], axis=1)
    p[:, 1] = np.stack([4.0 + 0.5 * t, np.zeros(n), np.full(n, 5.0)], axis=1)
    gap = 2.0 - (2.0 - dip_d) * np.exp(-(((t - dip_t) / 0.4) ** 2))
    z = 3.0 + 0.2 * t
    p[:, 2] = np.stack([2.0 - gap / 2, np.full(n, 3.0), z], axis=1)
    p[:, 3] = np.stack([2.0 + gap / 2, np.full(n, 3.0), z], axis=1)
    zeros = np.zeros_like(p)
    return {"t": t, "p": p, "v": zeros, "p_des": p + 0.01, "z1": p, "z2": zeros,
            "lumped_est": zeros, "lumped_true": zeros + 0.01,
            "min_dist": np.minimum(gap, 4.0) - 0.01}


def _world(polygon: bool = False) -> Any:
    obstacles = (
        Obstacle(ObstacleKind.SPHERE, (1.0, 1.0, 4.0), 0.5, radius_m=0.3),
        Obstacle(ObstacleKind.CYLINDER, (3.0, 1.5, 2.5), 0.5, radius_m=0.2,
                 z_range_m=(0.0, 5.0)),
        Obstacle(ObstacleKind.BOX, (5.0, 2.0, 4.0), 0.5, size_m=(0.4, 1.0, 0.4), yaw_deg=30.0),
    )
    fence = (polygon_fence(((-1.0, -1.0), (8.0, -1.0), (8.0, 5.0), (-1.0, 5.0)), (0.0, 9.0),
                           0.5)
             if polygon else Geofence((-1.0, -1.0, 0.0), (8.0, 5.0, 9.0), 0.5))
    return make_world(obstacles, fence)


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Every figure saved to a file (not the frames of an animation), kept open."""
    import matplotlib.figure

    saved: list[Any] = []
    real = matplotlib.figure.Figure.savefig

    def keep(self: Any, fname: Any, *a: Any, **k: Any) -> None:
        real(self, fname, *a, **k)
        if isinstance(fname, str | Path):
            saved.append(self)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return saved


def test_paths_mark_the_series_closest_approach(figures: list[Any], tmp_path: Path) -> None:
    s = _series()
    k = int(np.argmin(s["min_dist"]))
    ca = paths.plot_paths(s, tmp_path / "p.png", "x", FOLLOWERS, IDS, _world())
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert ca.distance_m == float(s["min_dist"].min())  # metrics.json's min_distance_m
    assert ca.t_s == pytest.approx(2.5) and ca.k == k and ca.t_s == s["t"][k]
    assert ca.pair == (2, 3) and ca.ids == (13, 14)
    (fig,) = figures
    top, side = fig.axes
    for ax, (a, b) in ((top, (0, 1)), (side, (0, 2))):
        (mark,) = [ln for ln in ax.get_lines() if ln.get_gid() == paths.CLOSEST_GID]
        xs, ys = mark.get_data()
        np.testing.assert_allclose(xs, s["p"][k, [2, 3], a])
        np.testing.assert_allclose(ys, s["p"][k, [2, 3], b])
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    label = next(x for x in legend if x.startswith("closest approach"))
    d, t = re.search(r"(\d+\.\d+) m at t = (\d+\.\d+) s", label).groups()  # type: ignore[union-attr]
    assert (float(d), float(t)) == (round(ca.distance_m, 3), round(ca.t_s, 2))
    assert "13–14" in label
    assert {"obstacles", "geofence", "vehicle 11", "start, t = 0.00 s", "end, t = 5.90 s"} <= set(
        legend)
    assert len(top.patches) == 4 and len(side.patches) == 4  # 3 obstacles and the fence


def test_polygon_fence_and_many_vehicles(figures: list[Any], tmp_path: Path) -> None:
    """A polygon fence is drawn as its polygon from above; 12 vehicles are coloured by role."""
    s = _series()
    s["p"] = np.concatenate([s["p"]] * 3, axis=1) + np.repeat(np.arange(3) * 10.0, 4)[:, None]
    paths.plot_paths(s, tmp_path / "p.png", "x", [2, 3, 6, 7, 10, 11], list(range(1, 13)),
                     _world(polygon=True))
    (fig,) = figures
    fence = fig.axes[0].patches[-1]
    assert len(fence.get_xy()) >= 4 and fence.get_linestyle() == "--"
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "leaders" in legend and "followers" in legend and "vehicle 1" not in legend


def _unit(label: str) -> bool:
    return bool(re.search(r"\([^()]*[A-Za-zµ°²³][^()]*\)\s*$", label))


def _check_axes(fig: Any) -> int:
    """Every axis of ``fig``: a label with its unit in parentheses; a categorical axis
    (text ticks, the methods) a label. Returns the axes checked."""
    n = 0
    for ax in fig.axes:
        axes = [ax.xaxis, ax.yaxis] + ([ax.zaxis] if hasattr(ax, "zaxis") else [])
        for axis in axes:
            label = axis.get_label().get_text()
            ticks = [t.get_text() for t in axis.get_ticklabels() if t.get_text()]
            categorical = bool(ticks) and not any(
                re.fullmatch(r"[−\-]?[\d.]+(e[−\-]?\d+)?|\$.*\$", t) for t in ticks)
            assert label, (ax.get_title(), axis.axis_name)
            assert categorical or _unit(label), (ax.get_title(), label)
            n += 1
    return n


@pytest.mark.full
def test_every_axis_of_every_figure_has_a_label_and_unit(
    figures: list[Any], tmp_path: Path
) -> None:
    """Each figure of the report as write_report draws it (one method, one snapshot)."""
    from swarm_common.scenario.mission_check import plan_for
    from swarm_common.scenario.model import load_scenario

    s = _series()
    series = {"rcbf": s}
    plots.plot_min_distance(series, 0.5, tmp_path / "a.png")
    plots.plot_errors(series, FOLLOWERS, tmp_path / "b.png")
    plots.plot_energy({"rcbf": {"energy_u": 1.0, "energy_thrust_excess": 0.5}},
                      tmp_path / "c.png")
    plots.plot_snapshots(s, EDGES, plots.snapshot_times(s, None)[1:2], tmp_path / "d.png",
                         "x", FOLLOWERS, _world())
    plan = plan_for(load_scenario(str(ROOT / "scenarios" / "course8.toml")))
    plots.plot_mission_path(series, plan, tmp_path / "e.png")
    paths.plot_paths(s, tmp_path / "f.png", "x", FOLLOWERS, IDS, _world())
    assert len(figures) == 6
    checked = sum(_check_axes(fig) for fig in figures)
    still, _ = animation.panels(s["p"], _world(), "x", s["t"], s["min_dist"])
    checked += _check_axes(still)
    # axes x their axes: min distance 2 x 2, errors 4 x 2, energy 2 x 2, a snapshot 1 x 3,
    # the mission path 1 x 2, the paths 2 x 2, the animation's still 3 x 2
    assert checked == 4 + 8 + 4 + 3 + 2 + 4 + 6


@pytest.fixture
def old_plots(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plots of gcs.report.plots not drawn (their captions are still written)."""
    for name in ("plot_min_distance", "plot_errors", "plot_snapshots", "plot_energy"):
        monkeypatch.setattr(plots, name, lambda *a, **k: None)


@pytest.mark.full
def test_each_figure_names_its_window_and_place_in_the_record(
    old_plots: None, tmp_path: Path
) -> None:
    s = _series()
    metrics = {"rcbf": {"min_distance_m": float(s["min_dist"].min()), "collisions": 0,
                        "energy_u": 1.0, "energy_thrust": 2.0, "energy_thrust_excess": 0.5,
                        "formation_time_s": None, "qp_fallbacks": 0, "h_min": 0.1}}
    text = write_report(tmp_path, "tiny", metrics, {"rcbf": s}, FOLLOWERS, EDGES, 0.5, [],
                        tau_safe_s=0.8, deadline_s=3.0, ids=IDS).read_text()
    lines = text.splitlines()
    images = [i for i, ln in enumerate(lines) if ln.startswith("![")]
    assert len(images) == 6  # min distance, errors, snapshots, energy, paths, animation
    for i in images:
        cap = lines[i + 2]
        assert cap.startswith("*Shows ") and "t = " in cap and " s" in cap, cap
        assert "In the record: " in cap and "`/" in cap, cap
    k = int(np.argmin(s["min_dist"]))
    at = f"`/pairs` at {s['t'][k]:.2f} s"
    paths_cap = lines[next(i for i in images if "paths_rcbf" in lines[i]) + 2]
    assert "t = 0.00–5.90 s" in paths_cap and "`rcbf/record.mcap`" in paths_cap
    assert f"13–14, {s['min_dist'].min():.3f} m at t = 2.50 s" in paths_cap and at in paths_cap
    gif_cap = lines[next(i for i in images if "closest_rcbf.gif" in lines[i]) + 2]
    assert "t = 0.00–5.50 s" in gif_cap and at in gif_cap  # 2.50 s ± 3 s, cut to the run
    assert f"`rcbf/record.mcap` {at}" in text  # the min-distance figure's caption


def test_without_the_writer_the_report_says_so_and_writes_no_gif(
    old_plots: None, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(matplotlib.animation.writers, "is_available", lambda name: False)
    s = _series()
    assert animation.animate_closest(s, tmp_path / "a.gif", "x", FOLLOWERS, IDS) is None
    metrics = {"rcbf": {"min_distance_m": 0.39, "collisions": 0, "energy_u": 1.0,
                        "energy_thrust": 2.0, "energy_thrust_excess": 0.5,
                        "formation_time_s": None, "qp_fallbacks": 0, "h_min": 0.1}}
    text = write_report(tmp_path, "tiny", metrics, {"rcbf": s}, FOLLOWERS, EDGES, 0.5, [],
                        tau_safe_s=0.8, deadline_s=3.0).read_text()
    assert list(tmp_path.rglob("*.gif")) == []
    assert text.count(animation.NO_WRITER) == 1 and "\n" not in animation.NO_WRITER
    assert ".gif" not in text and "(paths_rcbf.png)" in text


@pytest.mark.full
def test_the_gif_shows_the_window_around_the_closest_approach(tmp_path: Path) -> None:
    s = _series(dip_t=3.0, n=80)  # 0..7.9 s: the whole ±3 s window fits
    clip = animation.animate_closest(s, tmp_path / "a.gif", "x", FOLLOWERS, IDS, _world())
    assert clip is not None and clip.path.is_file()
    assert clip.closest.t_s == pytest.approx(3.0)
    assert clip.closest.distance_m == float(s["min_dist"].min())
    assert (clip.t0_s, clip.t1_s) == (pytest.approx(0.0), pytest.approx(6.0))
    with Image.open(clip.path) as im:
        assert im.format == "GIF" and im.n_frames == clip.frames == 61
        assert im.info["duration"] == 1000 // animation.FPS
    assert clip.path.stat().st_size < 300_000


def test_frame_steps() -> None:
    t = np.arange(300) * 0.02  # 50 Hz, 0..5.98 s
    steps = animation.frame_steps(t, 100, half_s=3.0, fps=10)  # t_k = 2.0 s
    assert 100 in steps
    np.testing.assert_allclose(np.diff(t[steps]), 0.1, atol=1e-9)
    assert t[steps[0]] == pytest.approx(0.0) and t[steps[-1]] == pytest.approx(5.0)
    odd = np.arange(0, 6, 0.03)  # 33 Hz: the nearest step to each frame time, t_k among them
    steps = animation.frame_steps(odd, 50, 1.0, 10)
    assert 50 in steps and np.all(np.diff(steps) > 0)
    assert np.all(np.abs(np.diff(odd[steps]) - 0.1) <= 0.03 + 1e-9)
