"""The figures of the comparison report (:func:`gcs.report.comparison.write_report`), each
under a caption line that names the time window it shows and where to see the same thing in
the run's record: the method's ``<method>/record.mcap`` beside ``report.md``, its topic and
time (the record's time is the series' ``t``; docs/records.md).

:func:`figure_lines` draws the plots of :mod:`gcs.report.plots`, the flown paths of
:mod:`gcs.report.paths` and the closest-approach animations of :mod:`gcs.report.animation`,
and returns the report's "Plots" and "Flown paths" sections.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gcs.report.shared import LABELS, closest_approach
from swarm_common.world.config import World


def record(method: str) -> str:
    """The record of ``method``'s run, relative to the report."""
    return f"`{method}/record.mcap`"


def span(series: dict[str, dict]) -> str:
    """The time window of the whole run (s), over every method's series."""
    ts = [s["t"] for s in series.values() if len(s["t"])]
    if not ts:
        return "no steps"
    return (f"t = {min(float(t[0]) for t in ts):.2f}–{max(float(t[-1]) for t in ts):.2f} s "
            "(the whole run)")


def caption(window: str, where: str) -> str:
    """The line under a figure: what time it shows, and where it is in the record."""
    return f"*Shows {window}. In the record: {where}.*"


def mission_caption(series: dict[str, dict]) -> str:
    """The caption of :func:`gcs.report.plots.plot_mission_path`'s figure."""
    runs = ", ".join(record(m) for m in series)
    return caption(span(series), f"open {runs}; `/world/tf` (true positions) and "
                                 "`/formation/desired` over the run")


def _plot_lines(
    d: Path, metrics: dict[str, dict], series: dict[str, dict], follower_idx: list[int],
    edges: list[tuple[int, int]], d_safe: float, world: World | None,
) -> list[str]:
    """Draw the plots of :mod:`gcs.report.plots`; the "Plots" section."""
    from gcs.report import plots

    whole = span(series)
    plots.plot_min_distance(series, d_safe, d / "min_distance.png")
    plots.plot_errors(series, follower_idx, d / "errors.png")
    plots.plot_energy(metrics, d / "energy.png")
    closest = []
    snaps: list[str] = []
    for m, s in series.items():
        times = plots.snapshot_times(s, metrics.get(m, {}).get("formation_time_s"))
        plots.plot_snapshots(s, edges, times, d / f"snapshots_{m}.png", LABELS.get(m, m),
                             follower_idx, world)
        k = closest_approach(s)[0]
        closest.append(f"{record(m)} `/pairs` at {float(s['t'][k]):.2f} s")
        at = ", ".join(f"{tt:.2f}" for tt, _ in times)
        snaps += [f"![snapshots {m}](snapshots_{m}.png)", "",
                  caption(f"t = {at} s", f"open {record(m)}; `/scene` and `/world/tf` at "
                                         "those times"), ""]
    return [
        "## Plots",
        "",
        "Smallest distance between any two vehicles; below, each method's closest approach.",
        "",
        "![min distance](min_distance.png)",
        "",
        caption(f"{whole}; below, ±{plots.ZOOM_S:g} s around each closest approach",
                f"`/pairs` `min_distance_m` of each method's {record('<method>')}; the "
                f"closest approaches: {'; '.join(closest)}"),
        "",
        "Tracking and estimation errors of the worst follower at each instant.",
        "",
        "![errors](errors.png)",
        "",
        caption(whole, f"open each method's {record('<method>')}; "
                       "`/agent/<id>/estimate` `track_err_m`, `p_err_m`, `v_err_m_s`, "
                       "`d_err_m_s2` of each follower"),
        "",
        "The formation at the start, at each method's closest approach, when it formed and",
        "at the end (times taken from the run).",
        "",
        *snaps,
        "![energy](energy.png)",
        "",
        caption(f"integrals over {whole}", f"open each method's {record('<method>')}; "
                                           "`/agent/<id>/qp` `u_m_s2` and `thrust_n` of each "
                                           "follower"),
        "",
    ]


def _path_lines(
    d: Path, series: dict[str, dict], follower_idx: list[int], ids: Sequence[int],
    world: World | None,
) -> list[str]:
    """Draw each method's paths and closest-approach animation; their section."""
    from gcs.report.animation import FPS, NO_WRITER, animate_closest, writer_available
    from gcs.report.paths import plot_paths

    gif = writer_available()
    lines = [
        "## Flown paths and the closest approach",
        "",
        "Each vehicle's path from above and from the side (ENU, m; hollow circle: start, "
        "square: end), the obstacles and geofence, and the closest approach: the pair "
        "nearest when the smallest distance of the run (`min_distance_m`) was measured.",
        "",
    ]
    if gif:
        lines += [f"Below each, the swarm around that moment ({FPS} frames per simulated "
                  "second, played in real time): the nearest pair ringed (red at the "
                  "closest approach), and under the views the smallest distance over the "
                  "window with a cursor at the frame's time.", ""]
    else:
        lines += [NO_WRITER, ""]
    for m, s in series.items():
        label = LABELS.get(m, m)
        ca = plot_paths(s, d / f"paths_{m}.png", label, follower_idx, ids, world)
        at = f"`/pairs` at {ca.t_s:.2f} s"
        lines += [
            f"### {label}",
            "",
            f"![paths {m}](paths_{m}.png)",
            "",
            caption(f"{span({m: s})}; closest approach {ca.ids[0]}–{ca.ids[1]}, "
                    f"{ca.distance_m:.3f} m at t = {ca.t_s:.2f} s",
                    f"open {record(m)}; `/world/tf` over the run, {at}"),
            "",
        ]
        clip = animate_closest(s, d / f"closest_{m}.gif", label, follower_idx, ids,
                               world) if gif else None
        if clip is not None:
            lines += [
                f"![closest approach {m}](closest_{m}.gif)",
                "",
                caption(f"t = {clip.t0_s:.2f}–{clip.t1_s:.2f} s ({clip.frames} frames)",
                        f"open {record(m)}; `/scene` and `/world/tf` from {clip.t0_s:.2f} "
                        f"to {clip.t1_s:.2f} s, {at}"),
                "",
            ]
    return lines


def figure_lines(
    d: Path,
    metrics: dict[str, dict],
    series: dict[str, dict],
    follower_idx: list[int],
    edges: list[tuple[int, int]],
    d_safe: float,
    ids: Sequence[int] | None = None,
    world: World | None = None,
) -> list[str]:
    """Draw every figure of the report into ``d``; the report's lines that show them, each
    with its caption (module docstring). ``ids``: the scenario's agent ids in column order
    (default 1, 2, ...)."""
    n = next((int(np.shape(s["p"])[1]) for s in series.values()), 0)
    ids_: Sequence[Any] = list(ids) if ids is not None else list(range(1, n + 1))
    return (_plot_lines(d, metrics, series, follower_idx, edges, d_safe, world)
            + _path_lines(d, series, follower_idx, ids_, world))
