"""Plots of the comparison report (matplotlib, Agg), written by
:func:`gcs.report.comparison.write_report`.

Minimum distance with a zoom on each method's closest approach, tracking and estimation
errors, 3-D formation snapshots at times taken from the run (start, closest approach,
formed, end) and energies. Positions are ENU (m); vehicles are indexed in scenario order.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from gcs.report.shared import LABELS, PAPER_TABLE3, closest_approach
from swarm_common.mission.plan import MissionPlan
from swarm_common.world.config import ObstacleKind, World

ZOOM_S = 0.6  # half-width of the closest-approach zoom (s)
TRAIL_S = 1.0  # length of the path drawn behind each vehicle in a snapshot (s)


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _tight(fig: Any) -> None:
    """``fig.tight_layout()``, then no layout engine: the one tight_layout leaves behind would
    make ``savefig`` lay the figure out again (the same picture; about 6 % of the report)."""
    fig.tight_layout()
    fig.set_layout_engine(None)


def plot_min_distance(series: dict[str, dict], d_safe: float, path: Path) -> None:
    """The whole run on top; below, one zoom per method around its closest approach."""
    plt = _plt()
    n = max(1, len(series))
    fig = plt.figure(figsize=(4 * n, 7.5))
    grid = fig.add_gridspec(2, n, height_ratios=(1.1, 1))
    top = fig.add_subplot(grid[0, :])
    for k, (m, s) in enumerate(series.items()):
        top.plot(s["t"], s["min_dist"], color=f"C{k}", label=LABELS.get(m, m), lw=1.0)
    top.axhline(d_safe, color="r", ls="--", label=f"D_safe = {d_safe:g} m")
    top.set(xlabel="time t (s)", ylabel="min distance, any pair (m)", ylim=(0, None))
    top.set_title("Smallest distance between any two vehicles", fontsize=10)
    top.grid(True, alpha=0.3)
    top.legend(fontsize=8, loc="best")
    for k, (m, s) in enumerate(series.items()):
        ax = fig.add_subplot(grid[1, k])
        i, dmin, (a, b) = closest_approach(s)
        t = s["t"]
        win = (t >= t[i] - ZOOM_S) & (t <= t[i] + ZOOM_S)
        ax.plot(t[win], s["min_dist"][win], color=f"C{k}", lw=1.2, label=LABELS.get(m, m))
        ax.axhline(d_safe, color="r", ls="--", label=f"D_safe = {d_safe:g} m")
        ax.plot([t[i]], [dmin], "kv", label=f"closest: {dmin:.3f} m at {t[i]:.2f} s")
        ax.set(xlabel="time t (s)", ylabel="min distance (m)", ylim=(0, None))
        ax.set_title(f"{LABELS.get(m, m)}: pair {a + 1}–{b + 1}", fontsize=9)
        ax.grid(True, alpha=0.3)
        # "best": the corner with the fewest points of the curve and the marker under it
        ax.legend(fontsize=7, loc="best")
    _tight(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_errors(series: dict[str, dict], follower_idx: list[int], path: Path) -> None:
    """Worst follower's tracking and estimation errors over time, with the paper's bounds."""
    plt = _plt()
    fig, axes = plt.subplots(4, 1, figsize=(8, 10), sharex=True)
    f = follower_idx
    for m, s in series.items():
        t = s["t"]
        trk = np.linalg.norm(s["p"][:, f] - s["p_des"][:, f], axis=2).max(axis=1)
        ep = np.linalg.norm(s["z1"][:, f] - s["p"][:, f], axis=2).max(axis=1)
        ev = np.linalg.norm(s["z2"][:, f] - s["v"][:, f], axis=2).max(axis=1)
        ed = np.linalg.norm(s["lumped_est"][:, f] - s["lumped_true"][:, f], axis=2).max(axis=1)
        for ax, y in zip(axes, (trk, ep, ev, ed), strict=True):
            ax.semilogy(t, np.maximum(y, 1e-4), label=LABELS.get(m, m), lw=0.8)
    names = (
        ("max tracking error (m)", 0.1, "formed tolerance"),
        ("max position est. error (m)", 0.05, "paper's bound"),
        ("max velocity est. error (m/s)", 0.1, "paper's bound"),
        ("max disturbance est. error (m/s²)", 0.15, "paper's bound"),
    )
    for ax, (lab, bound, what) in zip(axes, names, strict=True):
        ax.axhline(bound, color="k", ls=":", lw=0.8, label=f"{what}: {bound:g}")
        ax.set_ylabel(lab, fontsize=8)
        ax.set_xlabel("time t (s)", fontsize=8)  # every panel readable on its own
        ax.tick_params(labelbottom=True)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    axes[0].set_title("Worst follower at each instant (log scale)", fontsize=10)
    _tight(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def snapshot_times(s: dict, formed_s: float | None) -> list[tuple[float, str]]:
    """(time s, why) for the snapshots: start, closest approach, formed, end."""
    t = s["t"]
    k, dmin, (a, b) = closest_approach(s)
    out = [(float(t[0]), "start"), (float(t[k]), f"closest: {a + 1}–{b + 1} at {dmin:.2f} m")]
    if formed_s is not None:
        out.append((float(formed_s), "formed"))
    out.append((float(t[-1]), "end"))
    return out


def _draw_world(ax: Any, world: World) -> None:
    """The obstacles as grey wireframes (ENU, m)."""
    u, w = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
    for ob in world.obstacles:
        c = np.asarray(ob.centre_m)
        if ob.kind is ObstacleKind.SPHERE:
            r = ob.radius_m
            ax.plot_wireframe(c[0] + r * np.cos(u) * np.sin(w), c[1] + r * np.sin(u) * np.sin(w),
                              c[2] + r * np.cos(w), color="0.5", lw=0.4)
        elif ob.kind is ObstacleKind.CYLINDER:
            a, z = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.array(ob.z_range_m))
            ax.plot_wireframe(c[0] + ob.radius_m * np.cos(a), c[1] + ob.radius_m * np.sin(a), z,
                              color="0.5", lw=0.4)
        else:
            h = 0.5 * np.asarray(ob.size_m)
            corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * h
            yaw = np.deg2rad(ob.yaw_deg)
            rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0],
                            [0, 0, 1]])
            pts = corners @ rot.T + c
            for i in range(8):
                for j in range(i + 1, 8):
                    if int(np.sum(corners[i] != corners[j])) == 1:  # an edge
                        ax.plot(*zip(pts[i], pts[j], strict=True), color="0.5", lw=0.6)


def plot_snapshots(
    s: dict,
    edges: list[tuple[int, int]],
    times: list[tuple[float, str]],
    path: Path,
    title: str,
    follower_idx: list[int],
    world: World | None = None,
) -> None:
    """3-D formation at each of ``times`` (ENU, m): graph edges, the last second of each
    path, the nearest pair and the ``world``'s obstacles; the same axis limits in every
    panel."""
    plt = _plt()
    fig = plt.figure(figsize=(4.2 * len(times), 4.8))
    leaders = [i for i in range(s["p"].shape[1]) if i not in follower_idx]
    lo, hi = s["p"].reshape(-1, 3).min(axis=0) - 0.3, s["p"].reshape(-1, 3).max(axis=0) + 0.3
    for n, (tt, why) in enumerate(times):
        i = int(np.clip(np.searchsorted(s["t"], tt - 1e-9), 0, len(s["t"]) - 1))
        ax = fig.add_subplot(1, len(times), n + 1, projection="3d")
        p = s["p"][i]
        for a, b in edges:
            ax.plot(*zip(p[a], p[b], strict=True), color="0.8", lw=0.5)
        trail = s["p"][(s["t"] >= s["t"][i] - TRAIL_S) & (s["t"] <= s["t"][i])]
        for j in range(p.shape[0]):
            ax.plot(trail[:, j, 0], trail[:, j, 1], trail[:, j, 2], color="0.35", lw=0.7)
        ax.scatter(*p[leaders].T, c="r", s=20, label="leaders")
        ax.scatter(*p[follower_idx].T, c="b", s=20, label="followers")
        d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        d[np.diag_indices(len(p))] = np.inf
        na, nb = (int(x) for x in np.unravel_index(int(np.argmin(d)), d.shape))
        # the recorded smallest distance of this step: the number the closest-approach
        # title shows (snapshot_times), so title and legend agree to the last digit
        near = f"nearest pair {float(s['min_dist'][i]):.2f} m"
        ax.plot(*zip(p[na], p[nb], strict=True), "m-", lw=2.0, label=near)
        if world is not None:
            _draw_world(ax, world)
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
        ax.set_box_aspect(None, zoom=0.82)
        ax.set_title(f"t = {s['t'][i]:.2f} s ({why})", fontsize=8)
        ax.set_xlabel("x east (m)", fontsize=7)
        ax.set_ylabel("y north (m)", fontsize=7)
        ax.set_zlabel("z up (m)", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=6, loc="upper left")
    fig.suptitle(f"{title}: formation (light grey: graph edges; dark: paths over the last 1 s)")
    _tight(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_energy(metrics: dict[str, dict], path: Path) -> None:
    """Our energies beside the paper's Table 3 column."""
    plt = _plt()
    ms = list(metrics)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    x = np.arange(len(ms))
    axes[0].bar(x, [metrics[m]["energy_u"] for m in ms], color="C0", label="ours ∫Σ‖u‖²dt")
    paper = [PAPER_TABLE3.get(m, (0, np.nan))[1] for m in ms]
    axes[0].plot(x, paper, "k*", ms=10, label="paper Table 3 (no unit)")
    axes[0].set(ylabel="∫Σ‖u‖²dt (m²/s³)", title="Squared virtual control (followers)")
    excess = [metrics[m]["energy_thrust_excess"] for m in ms]
    axes[1].bar(x, excess, color="C1", label="ours ∫Σ(F − mg)²dt")
    axes[1].set(ylabel="∫Σ(F − mg)²dt (N²s)", title="Squared thrust above hover (followers)")
    for ax in axes:
        # the methods' labels are long: wrapped onto lines of at most 12 characters so that
        # neighbours never overlap (four methods on a 4-inch axis)
        ax.set_xticks(x, [textwrap.fill(LABELS.get(m, m), 12) for m in ms], fontsize=7)
        ax.set_xlabel("method")
        ax.title.set_fontsize(9)
        ax.legend(fontsize=8)
    _tight(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_mission_path(series: dict[str, dict], plan: MissionPlan, path: Path) -> None:
    """The formation mission from above (ENU x east, y north, m): the planned centroid path,
    each method's flown centroid (the mean of every agent's true position) and the
    waypoints, numbered from 0 in file order."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    t = np.linspace(0.0, plan.end_s, max(200, int(plan.end_s * 20)))
    planned = np.array([plan.centroid_at(x) for x in t])
    ax.plot(planned[:, 0], planned[:, 1], "k--", lw=1.2, label="planned centroid")
    for m, s in series.items():
        c = s["p"].mean(axis=1)
        ax.plot(c[:, 0], c[:, 1], lw=1.0, label=f"flown centroid ({m})")
        last = s["p"][-1]
        ax.scatter(last[:, 0], last[:, 1], s=8, alpha=0.6)
    for k, leg in enumerate(plan.legs):
        x, y = leg.end.centroid[0], leg.end.centroid[1]
        ax.plot(x, y, "o", mfc="none", mec="r", ms=9)
        ax.annotate(str(k), (x, y), textcoords="offset points", xytext=(6, 6), fontsize=8)
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("Formation mission from above (red circles: waypoints; dots: agents at the end)",
                 fontsize=8)
    ax.legend(fontsize=7)
    _tight(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)
