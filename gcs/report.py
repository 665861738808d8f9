"""Comparison report of the three methods: Table 3 beside ours, and plots (matplotlib, Agg).

Energy (errata 15): the paper's "integral of squared thrust" cannot be ∫ΣF²dt (hover alone
gives ~1.1·10⁵ N²s per minute for six vehicles); we print ``energy_u = ∫Σ‖u_i‖²dt`` (the
column compared with the paper's numbers), ``∫Σ(F−mg)²dt`` and ``∫ΣF²dt``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

PAPER_TABLE3 = {"rcbf": (0.75, 236.41), "apf": (0.37, 1115.23), "none": (0.10, 189.52)}
LABELS = {"rcbf": "Proposed RCBF", "apf": "Improved APF", "none": "No collision avoidance"}


def _f(x: Any, nd: int = 2) -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        return f"{x:.{nd}f}"
    return str(x)


def compare_table(metrics: dict[str, dict], d_safe: float = 0.5) -> str:
    """Markdown table: paper Table 3 beside our metrics per method."""
    head = (
        "| Method | Paper min dist (m) | Ours min dist (m) | < D_safe | collisions | "
        "Paper energy | Ours ∫Σ‖u‖²dt | ∫Σ(F−mg)²dt | ∫ΣF²dt | formed (s) | "
        "track RMS/max (m) | QP fallbacks |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    rows = []
    for m, met in metrics.items():
        pd, pe = PAPER_TABLE3.get(m, (None, None))
        trk = f"{_f(met.get('tracking_rms_m'), 3)} / {_f(met.get('tracking_max_m'), 3)}"
        rows.append(
            f"| {LABELS.get(m, m)} | {_f(pd)} | {_f(met['min_distance_m'], 3)} | "
            f"{'yes' if met['min_distance_m'] < d_safe else 'no'} | {met['collisions']} | "
            f"{_f(pe)} | {_f(met['energy_u'], 1)} | {_f(met['energy_thrust_excess'], 1)} | "
            f"{_f(met['energy_thrust'], 0)} | {_f(met.get('formation_time_s'), 1)} | {trk} | "
            f"{met['qp_fallbacks']} |"
        )
    return head + "\n".join(rows) + "\n"


def seeds_table(dist: dict[str, list[dict]], d_safe: float = 0.5) -> str:
    """Markdown table of the min-distance distribution over seeds per method."""
    out = (
        "| Method | seeds | min dist: min / median / max (m) | runs < D_safe | collisions "
        "(total) | ∫Σ‖u‖²dt median | formed (s) median |\n|---|---|---|---|---|---|---|\n"
    )
    for m, runs in dist.items():
        md = np.array([r["min_distance_m"] for r in runs])
        col = sum(r["collisions"] for r in runs)
        eu = np.median([r["energy_u"] for r in runs])
        ft = [r["formation_time_s"] for r in runs if r["formation_time_s"] is not None]
        ftm = f"{np.median(ft):.1f} ({len(ft)}/{len(runs)} formed)" if ft else "never"
        out += (
            f"| {LABELS.get(m, m)} | {len(runs)} | {md.min():.3f} / {np.median(md):.3f} / "
            f"{md.max():.3f} | {int(np.sum(md < d_safe))} | {col} | {eu:.1f} | {ftm} |\n"
        )
    return out


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_min_distance(series: dict[str, dict], d_safe: float, path: Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    for m, s in series.items():
        ax.plot(s["t"], s["min_dist"], label=LABELS.get(m, m))
    ax.axhline(d_safe, color="r", ls="--", label=f"D_safe = {d_safe} m")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("min inter-agent distance (m)")
    ax.set_ylim(0, None)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_errors(series: dict[str, dict], follower_idx: list[int], path: Path) -> None:
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
        ("max tracking error (m)", 0.1),
        ("max position est. error (m)", 0.05),
        ("max velocity est. error (m/s)", 0.1),
        ("max disturbance est. error (m/s²)", 0.15),
    )
    for ax, (lab, bound) in zip(axes, names, strict=True):
        ax.axhline(bound, color="k", ls=":", lw=0.8)
        ax.set_ylabel(lab, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_snapshots(
    s: dict, edges: list[tuple[int, int]], times: tuple[float, ...], path: Path, title: str
) -> None:
    plt = _plt()
    fig = plt.figure(figsize=(12, 3.6))
    for k, tt in enumerate(times):
        i = int(np.clip(np.searchsorted(s["t"], tt), 0, len(s["t"]) - 1))
        ax = fig.add_subplot(1, len(times), k + 1, projection="3d")
        p = s["p"][i]
        for a, b in edges:
            ax.plot(*zip(p[a], p[b], strict=True), color="0.7", lw=0.6)
        ax.scatter(p[:2, 0], p[:2, 1], p[:2, 2], c="r", s=20, label="leaders")
        ax.scatter(p[2:, 0], p[2:, 1], p[2:, 2], c="b", s=20, label="followers")
        ax.set_title(f"t = {s['t'][i]:.0f} s", fontsize=9)
        ax.tick_params(labelsize=6)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_energy(metrics: dict[str, dict], path: Path) -> None:
    plt = _plt()
    ms = list(metrics)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    x = np.arange(len(ms))
    axes[0].bar(x, [metrics[m]["energy_u"] for m in ms], color="C0", label="ours ∫Σ‖u‖²dt")
    axes[0].plot(x, [PAPER_TABLE3.get(m, (0, np.nan))[1] for m in ms], "k*", ms=10,
                 label="paper Table 3")
    axes[0].legend(fontsize=8)
    axes[1].bar(x, [metrics[m]["energy_thrust_excess"] for m in ms], color="C1")
    axes[1].set_title("∫Σ(F − mg)² dt (N²s)", fontsize=9)
    for ax in axes:
        ax.set_xticks(x, [LABELS.get(m, m) for m in ms], fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(
    out_dir: str | Path,
    scenario_name: str,
    metrics: dict[str, dict],
    series: dict[str, dict],
    follower_idx: list[int],
    edges: list[tuple[int, int]],
    d_safe: float,
    gains: list[str],
    seeds: dict[str, list[dict]] | None = None,
    mode: str = "in-process",
) -> Path:
    """Write report.md and the PNG plots into ``out_dir``; returns the report path."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    plot_min_distance(series, d_safe, d / "min_distance.png")
    plot_errors(series, follower_idx, d / "errors.png")
    for m, s in series.items():
        snap = d / f"snapshots_{m}.png"
        plot_snapshots(s, edges, (0.0, 10.0, 20.0, 50.0), snap, LABELS.get(m, m))
    plot_energy(metrics, d / "energy.png")
    lines = [
        f"# Mission comparison: {scenario_name}",
        "",
        f"Paper Table 3 beside our {mode} runs (same scenario, seed, sensing noise, ζ).",
        "Energy: the paper's column is compared with ∫Σ‖u_i‖²dt over the followers (errata 15).",
        "",
        compare_table(metrics, d_safe),
    ]
    if seeds:
        lines += ["## Distribution over seeds", "", seeds_table(seeds, d_safe)]
    lines += [
        "## Observer gain check",
        "",
        "```",
        *gains,
        "```",
        "",
        "![min distance](min_distance.png)",
        "",
        "![errors](errors.png)",
        "",
        *[f"![snapshots {m}](snapshots_{m}.png)\n" for m in series],
        "![energy](energy.png)",
        "",
    ]
    path = d / "report.md"
    path.write_text("\n".join(lines))
    return path
