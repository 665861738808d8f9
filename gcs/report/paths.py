"""The flown paths of a run from above (x east, y north) and from the side (x east, z up),
ENU metres, written by :func:`gcs.report.comparison.write_report`.

Every vehicle's whole path with its start (hollow circle) and end (filled square), the
scenario's obstacles (grey) and geofence (dashed), and the run's closest approach: the
pair nearest at the step where the series' ``min_dist`` is smallest, joined by a magenta
segment and named with that distance and time (``metrics.json``'s ``min_distance_m``).
The same plan and side views, drawn with the obstacles and fence by
:func:`draw_world_2d` and framed by :func:`view_limits`, are the panels of the
closest-approach animation (:mod:`gcs.report.animation`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from gcs.report.shared import closest_approach
from swarm_common.world.config import ObstacleKind, World

MARGIN_M = 0.5  # space around the paths (m)
WORLD_REACH_M = 3.0  # obstacles and fence widen the view by at most this past the paths (m)
MAX_VEHICLE_COLOURS = 10  # more vehicles: coloured by role, not one colour each
CLOSEST_GID = "closest-approach"  # gid of the segment that marks the closest approach
OBSTACLE_STYLE: dict[str, Any] = {"fc": "0.8", "ec": "0.45", "lw": 0.6, "zorder": 1}
FENCE_STYLE: dict[str, Any] = {"fill": False, "ec": "k", "ls": "--", "lw": 0.8, "zorder": 1}


def pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend (files only, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


class View(StrEnum):
    """Which ENU plane a panel shows: from above (x, y) or from the south side (x, z)."""

    TOP = "top"
    SIDE = "side"

    @property
    def axes(self) -> tuple[int, int]:
        """The ENU components on the panel's horizontal and vertical axes."""
        return (0, 1) if self is View.TOP else (0, 2)

    @property
    def labels(self) -> tuple[str, str]:
        return ("x east (m)", "y north (m)") if self is View.TOP else ("x east (m)", "z up (m)")


@dataclass(frozen=True)
class Closest:
    """The closest approach of a run, as marked in the figures."""

    k: int  # the step
    t_s: float  # its time (s, the series' t; the record's time)
    distance_m: float  # the series' min_dist there: metrics.json's min_distance_m
    pair: tuple[int, int]  # the nearest pair at that step, column indices
    ids: tuple[int, int]  # the same pair, scenario ids


def closest_of(s: dict, ids: Sequence[int]) -> Closest:
    """The closest approach of the series ``s`` (:func:`gcs.report.shared.closest_approach`),
    its pair also named by ``ids`` (scenario ids, column order)."""
    k, d, (a, b) = closest_approach(s)
    return Closest(k, float(s["t"][k]), d, (a, b), (int(ids[a]), int(ids[b])))


def _obstacle_patch(ob: Any, view: View) -> Any:
    """One obstacle seen from above or from the side, as a matplotlib patch."""
    from matplotlib.patches import Circle, Polygon, Rectangle

    c = np.asarray(ob.centre_m, dtype=float)
    if ob.kind is ObstacleKind.SPHERE:
        return Circle((c[0], c[view.axes[1]]), ob.radius_m, **OBSTACLE_STYLE)
    if ob.kind is ObstacleKind.CYLINDER:
        if view is View.TOP:
            return Circle((c[0], c[1]), ob.radius_m, **OBSTACLE_STYLE)
        z0, z1 = ob.z_range_m
        return Rectangle((c[0] - ob.radius_m, z0), 2 * ob.radius_m, z1 - z0, **OBSTACLE_STYLE)
    h = 0.5 * np.asarray(ob.size_m, dtype=float)
    yaw = np.deg2rad(ob.yaw_deg)
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * h[:2] @ rot.T + c[:2]
    if view is View.TOP:
        return Polygon(corners, closed=True, **OBSTACLE_STYLE)
    x0, x1 = corners[:, 0].min(), corners[:, 0].max()  # the box's shadow on the x-z plane
    return Rectangle((x0, c[2] - h[2]), x1 - x0, 2 * h[2], **OBSTACLE_STYLE)


def draw_world_2d(ax: Any, world: World | None, view: View) -> list[str]:
    """Draw ``world``'s obstacles and geofence on ``ax`` as seen from ``view``; returns
    what was drawn ("obstacles", "geofence") for the legend."""
    from matplotlib.patches import Polygon, Rectangle

    if world is None:
        return []
    for ob in world.obstacles:
        ax.add_patch(_obstacle_patch(ob, view))
    drawn = ["obstacles"] if world.obstacles else []
    f = world.geofence
    if f is not None:
        if view is View.TOP and f.polygon_m:
            ax.add_patch(Polygon(np.array(f.polygon_m), closed=True, **FENCE_STYLE))
        else:
            a, b = view.axes
            ax.add_patch(Rectangle((f.min_m[a], f.min_m[b]), f.max_m[a] - f.min_m[a],
                                   f.max_m[b] - f.min_m[b], **FENCE_STYLE))
        drawn.append("geofence")
    return drawn


def _world_box(world: World | None) -> tuple[np.ndarray, np.ndarray] | None:
    """The ENU bounding box (lo, hi) of ``world``'s obstacles and fence, m; None if empty."""
    if world is None or world.empty:
        return None
    lo, hi = [], []
    for ob in world.obstacles:
        c = np.asarray(ob.centre_m, dtype=float)
        if ob.kind is ObstacleKind.BOX:
            r = np.full(3, 0.5 * float(np.linalg.norm(ob.size_m)))
        elif ob.kind is ObstacleKind.CYLINDER:
            (z0, z1), r = ob.z_range_m, np.full(3, ob.radius_m)
            c[2], r[2] = 0.5 * (z0 + z1), 0.5 * (z1 - z0)
        else:
            r = np.full(3, ob.radius_m)
        lo.append(c - r)
        hi.append(c + r)
    if world.geofence is not None:
        lo.append(np.asarray(world.geofence.min_m, dtype=float))
        hi.append(np.asarray(world.geofence.max_m, dtype=float))
    return np.min(lo, axis=0), np.max(hi, axis=0)


def view_limits(p: np.ndarray, world: World | None) -> tuple[np.ndarray, np.ndarray]:
    """ENU (lo, hi) that frame the positions ``p`` (..., 3) with :data:`MARGIN_M` around them,
    widened to show ``world`` but by at most :data:`WORLD_REACH_M` past the positions."""
    pts = p.reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    plo, phi = (pts.min(axis=0), pts.max(axis=0)) if len(pts) else (np.zeros(3), np.ones(3))
    lo, hi = plo - MARGIN_M, phi + MARGIN_M
    box = _world_box(world)
    if box is not None:
        lo = np.minimum(lo, np.maximum(box[0] - 0.2, plo - WORLD_REACH_M))
        hi = np.maximum(hi, np.minimum(box[1] + 0.2, phi + WORLD_REACH_M))
    return lo, hi


def vehicle_colours(n: int, follower_idx: Sequence[int]) -> list[Any]:
    """A colour per vehicle: one each (tab10) up to :data:`MAX_VEHICLE_COLOURS` vehicles;
    beyond, leaders red and followers blue."""
    from matplotlib import colormaps

    if n <= MAX_VEHICLE_COLOURS:
        return [colormaps["tab10"](j) for j in range(n)]
    return ["C0" if j in follower_idx else "C3" for j in range(n)]


def plot_paths(
    s: dict,
    path: Path,
    title: str,
    follower_idx: Sequence[int],
    ids: Sequence[int],
    world: World | None = None,
) -> Closest:
    """The top and side views of every vehicle's path over the whole run (module docstring)
    into ``path``; returns the closest approach marked."""
    plt = pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    p, t = s["p"], s["t"]
    n = p.shape[1]
    ca = closest_of(s, ids)
    colours = vehicle_colours(n, follower_idx)
    lo, hi = view_limits(p, world)
    fig, axes = plt.subplots(1, 2, figsize=(11.5, 5.0))
    drawn: list[str] = []
    for ax, view in zip(axes, (View.TOP, View.SIDE), strict=True):
        a, b = view.axes
        drawn = draw_world_2d(ax, world, view)
        # one artist per kind, not per vehicle: the figure's cost is its artists
        ax.add_collection(LineCollection([p[:, j][:, [a, b]] for j in range(n)],
                                         colors=colours, lw=0.9, alpha=0.85))
        ax.scatter(p[0, :, a], p[0, :, b], s=36, marker="o", facecolors="none",
                   edgecolors=colours)
        ax.scatter(p[-1, :, a], p[-1, :, b], s=25, marker="s", c=colours)
        pa, pb = p[ca.k, ca.pair[0]], p[ca.k, ca.pair[1]]
        ax.plot([pa[a], pb[a]], [pa[b], pb[b]], "m-*", lw=2.0, ms=9, zorder=5, gid=CLOSEST_GID)
        ax.annotate(f"{ca.ids[0]}–{ca.ids[1]}", (pa[a], pa[b]), xytext=(7, 7), color="m",
                    textcoords="offset points", fontsize=8, zorder=6)
        ax.set(xlim=(lo[a], hi[a]), ylim=(lo[b], hi[b]), xlabel=view.labels[0],
               ylabel=view.labels[1])
        ax.set_aspect("equal", adjustable="box")
        ax.set_title("from above" if view is View.TOP else "from the side (south)", fontsize=9)
        ax.grid(True, alpha=0.3)
    handles: list[Any] = (
        [Line2D([], [], color=colours[j], lw=1.2, label=f"vehicle {ids[j]}") for j in range(n)]
        if n <= MAX_VEHICLE_COLOURS
        else [Line2D([], [], color="C3", label="leaders"),
              Line2D([], [], color="C0", label="followers")])
    handles += [
        Line2D([], [], ls="", marker="o", mfc="none", mec="k", label=f"start, t = {t[0]:.2f} s"),
        Line2D([], [], ls="", marker="s", color="k", label=f"end, t = {t[-1]:.2f} s"),
        Line2D([], [], color="m", marker="*", lw=2.0,
               label=f"closest approach: {ca.ids[0]}–{ca.ids[1]},\n"
                     f"{ca.distance_m:.3f} m at t = {ca.t_s:.2f} s"),
    ]
    if "obstacles" in drawn:
        handles.append(Patch(fc="0.8", ec="0.45", label="obstacles"))
    if "geofence" in drawn:
        handles.append(Line2D([], [], color="k", ls="--", lw=0.8, label="geofence"))
    fig.legend(handles=handles, loc="center right", fontsize=7, frameon=False)
    fig.suptitle(f"{title}: flown paths, t = {t[0]:.2f}–{t[-1]:.2f} s (ENU)", fontsize=10)
    # fixed margins, not tight_layout: its measuring and the extra draw it leaves behind
    # would double the figure's cost
    fig.subplots_adjust(left=0.06, right=0.83, bottom=0.1, top=0.88, wspace=0.22)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return ca
