"""What ``gcs mission sweep`` writes: ``runs.csv``, ``summary.md`` and ``summary.png``.

``runs.csv``: one row per (scenario, method, seed), columns :data:`CSV_COLUMNS` (the run's
metrics of :mod:`gcs.report.metrics`, the per-phase minimum distances flattened to
``min_distance_<phase>_m``; empty cells for null values and for crashed runs).

``summary.md``: per scenario × method, percentiles p0/p5/p50 of the minimum distance and of
the true barrier minimum h_min, runs with a barrier violation, collisions, and the 95 %
Clopper–Pearson upper bound on the per-run probability of a violation
(:func:`clopper_pearson_upper`); per scenario × method the safety, success and alarm rates
with one-sided Clopper–Pearson bounds and two-sided 95 % Wilson score intervals
(:func:`wilson_interval`). Definitions: docs/metrics.md. Also the seed table of
``gcs mission compare --seeds N`` (:func:`seeds_table`).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gcs.report.metrics import LIST_KEYS, METRIC_KEYS, PHASES
from gcs.report.shared import FORMED_TOL_M, LABELS, md_legend
from swarm_common.scenario.model import Scenario

ID_COLUMNS = ("scenario", "method", "seed", "status", "error", "duration_s")
METRIC_COLUMNS = tuple(
    c for k in METRIC_KEYS if k not in LIST_KEYS
    for c in ([f"min_distance_{p}_m" for p in PHASES] if k == "min_distance_by_phase_m" else [k])
)
CSV_COLUMNS = ID_COLUMNS + METRIC_COLUMNS
PERCENTILES = (0, 5, 50)
CONFIDENCE = 0.95


def flat_row(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """A run's metrics as flat CSV cells (per-phase distances spread over columns)."""
    row = {k: v for k, v in metrics.items()
           if k != "min_distance_by_phase_m" and k not in LIST_KEYS}
    phases = metrics.get("min_distance_by_phase_m") or {}
    row.update({f"min_distance_{p}_m": phases.get(p) for p in PHASES})
    return row


def clopper_pearson_upper(x: int, n: int, conf: float = CONFIDENCE) -> float:
    """One-sided upper confidence bound on a probability from ``x`` events in ``n`` trials
    (Clopper–Pearson, exact): the p with P(X ≤ x | n, p) = 1 − conf, i.e. the ``conf``
    quantile of Beta(x + 1, n − x). With x = 0 this is 1 − (1 − conf)^(1/n) ≈ 3/n."""
    if n <= 0:
        return 1.0
    if x >= n:
        return 1.0
    from scipy.stats import beta  # here: importing scipy.stats costs every gcs command 0.3 s

    return float(beta.ppf(conf, x + 1, n - x))


def seeds_table(dist: dict[str, list[dict]], d_safe: float = 0.5) -> str:
    """Markdown table of the min-distance distribution over seeds per method."""
    out = (
        "| Method | Seeds | Min dist: min / median / max (m) | Runs < D_safe | Collisions "
        "(total) | ∫Σ‖u‖²dt median (m²/s³) | Formed at median (s) |\n"
        "|---|---|---|---|---|---|---|\n"
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


def seeds_legend(d_safe: float = 0.5) -> str:
    """Definition and unit of every column of :func:`seeds_table`."""
    return md_legend(
        [
            (
                "Seeds",
                "number of runs, each with its own random seed (sensing noise, "
                "disturbances); the scenario is otherwise the same.",
            ),
            (
                "Min dist: min / median / max (m)",
                "over the runs, of each run's smallest distance between any two vehicles.",
            ),
            ("Runs < D_safe", f"runs whose smallest distance is below D_safe = {d_safe:g} m."),
            (
                "Collisions (total)",
                "contact events (closer than the collision radius) summed over all runs.",
            ),
            (
                "∫Σ‖u‖²dt median (m²/s³)",
                "median over the runs of the integral of the followers' squared virtual control.",
            ),
            (
                "Formed at median (s)",
                f"median over the runs that formed (every follower within "
                f"{FORMED_TOL_M:g} m to the end) of the formation time, with how many formed.",
            ),
        ]
    )


def csv_cells(row: Mapping[str, Any]) -> dict[str, Any]:
    """A row's :data:`CSV_COLUMNS` cells; None → empty cell."""
    return {k: "" if row.get(k) is None else row.get(k) for k in CSV_COLUMNS}


def write_csv(path: Path, rows: Iterable[Mapping[str, Any]]) -> None:
    """``runs.csv``, sorted by scenario, method, seed; None → empty cell."""
    ordered = sorted(rows, key=lambda r: (r["scenario"], r["method"], int(r["seed"])))
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(CSV_COLUMNS), extrasaction="ignore")
        w.writeheader()
        for r in ordered:
            w.writerow(csv_cells(r))


def _pcts(values: list[float]) -> str:
    if not values:
        return "–"
    return " / ".join(f"{np.percentile(values, q):.3f}" for q in PERCENTILES)


def group_stats(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Statistics of the runs of one scenario × method (crashed runs counted apart)."""
    ok = [r for r in rows if r["status"] == "ok"]
    n = len(ok)
    viol = sum(1 for r in ok if (r.get("barrier_violation_steps") or 0) > 0)
    coll_runs = sum(1 for r in ok if (r.get("collisions") or 0) > 0)
    return {
        "runs": n,
        "crashed": len(rows) - n,
        "min_distance_m": [float(r["min_distance_m"]) for r in ok],
        "h_min": [float(r["h_min"]) for r in ok if r.get("h_min") is not None],
        "violation_runs": viol,
        "violation_steps": sum(int(r.get("barrier_violation_steps") or 0) for r in ok),
        "collision_runs": coll_runs,
        "collisions": sum(int(r.get("collisions") or 0) for r in ok),
        "ground_strikes": sum(int(r.get("ground_strikes") or 0) for r in ok),
        "clipped_steps": sum(int(r.get("input_clipped_steps") or 0) for r in ok),
        "formed": sum(1 for r in ok if r.get("formation_time_s") not in (None, "")),
        "violation_p_upper": clopper_pearson_upper(viol, n) if n else None,
        "collision_p_upper": clopper_pearson_upper(coll_runs, n) if n else None,
    }


SUMMARY_HEAD = (
    "| Scenario | Method | Runs (crashed) | Min dist p0 / p5 / p50 (m) | "
    "True h_min p0 / p5 / p50 (m²) | Runs with h<0 | Steps h<0 (total) | "
    "Runs with collision (contacts) | P(violation) 95 % UB | P(collision) 95 % UB | "
    "Ground strikes | Clipped steps | Formed |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
)


def summary_table(rows: Sequence[Mapping[str, Any]], methods: list[str]) -> str:
    """The markdown table of ``summary.md`` (one line per scenario × method)."""
    out = SUMMARY_HEAD
    for scen in sorted({r["scenario"] for r in rows}):
        for m in methods:
            grp = [r for r in rows if r["scenario"] == scen and r["method"] == m]
            if not grp:
                continue
            g = group_stats(grp)
            ub = "–" if g["violation_p_upper"] is None else f"{g['violation_p_upper']:.3f}"
            cub = "–" if g["collision_p_upper"] is None else f"{g['collision_p_upper']:.3f}"
            out += (
                f"| {scen} | {m} | {g['runs']} ({g['crashed']}) | {_pcts(g['min_distance_m'])} | "
                f"{_pcts(g['h_min'])} | {g['violation_runs']}/{g['runs']} | "
                f"{g['violation_steps']} | {g['collision_runs']}/{g['runs']} "
                f"({g['collisions']}) | {ub} | {cub} | {g['ground_strikes']} | "
                f"{g['clipped_steps']} | {g['formed']}/{g['runs']} |\n"
            )
    return out


MISSION_HEAD = (
    "| Scenario | Method | Runs | Completed | P(not completed) 95 % UB | "
    "Transit rms p50 / max (m) | Transit max, worst run (m) | Observer error, worst run (m) |\n"
    "|---|---|---|---|---|---|---|---|\n"
)


def mission_table(rows: Sequence[Mapping[str, Any]], methods: list[str]) -> str | None:
    """The formation missions' table of ``summary.md`` (docs/missions.md): per scenario ×
    method with a mission, completed runs, the transit error and the observer's error; None
    when no scenario of the sweep has a mission."""
    out = MISSION_HEAD
    any_mission = False
    for scen in sorted({r["scenario"] for r in rows}):
        for m in methods:
            ok = [r for r in rows if r["scenario"] == scen and r["method"] == m
                  and r["status"] == "ok" and r.get("mission_completed") is not None]
            if not ok:
                continue
            any_mission = True
            n = len(ok)
            done = sum(1 for r in ok if r["mission_completed"] is True)
            rms = [float(r["transit_error_rms_m"]) for r in ok
                   if r.get("transit_error_rms_m") is not None]
            tmax = [float(r["transit_error_max_m"]) for r in ok
                    if r.get("transit_error_max_m") is not None]
            ref = [float(r["ref_est_max_m"]) for r in ok if r.get("ref_est_max_m") is not None]
            out += (
                f"| {scen} | {m} | {n} | {done}/{n} | {clopper_pearson_upper(n - done, n):.3f} "
                f"| {_stat(rms, 50)} / {_stat(rms, 100)} | {_stat(tmax, 100)} "
                f"| {_stat(ref, 100)} |\n"
            )
    return out if any_mission else None


RATES_HEAD = (
    "| Scenario | Method | Runs | Safe (95 % LB) | Success (95 % LB) | Alarmed (95 % UB) | "
    "Stalled | Safe 95 % CI | Success 95 % CI | Alarmed 95 % CI |\n"
    "|---|---|---|---|---|---|---|---|---|---|\n"
)
Z_95 = 1.959963984540054  # the standard normal's 0.975 quantile


def wilson_interval(x: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """Two-sided Wilson score interval on a probability from ``x`` events in ``n`` trials:
    the p with |x/n − p| ≤ z √(p(1 − p)/n) (z = 1.96: 95 %); (0, 1) when n = 0."""
    if n <= 0:
        return (0.0, 1.0)
    p_hat = x / n
    z2n = z * z / n
    centre = (p_hat + z2n / 2) / (1 + z2n)
    half = z / (1 + z2n) * float(np.sqrt(p_hat * (1 - p_hat) / n + z2n / (4 * n)))
    return (max(0.0, centre - half), min(1.0, centre + half))


def _wilson_cell(x: int, n: int) -> str:
    lo, hi = wilson_interval(x, n)
    return f"{lo:.3f}–{hi:.3f}"


def run_rates(ok: Sequence[Mapping[str, Any]]) -> tuple[int, int, int, int]:
    """(safe, successful, alarmed, stalled) runs among finished ones: **safe** when the
    safety verdict is not "unsafe" (the true barrier ≥ 0 at every step, no contact, no
    ground strike); **successful** when the formation formed (``formation_time_s`` set) or,
    for a mission, the mission completed; **alarmed** when the verdict is not "safe" (a
    safety event of the truth or of an agent: docs/metrics.md); **stalled** when an agent
    raised the DEADLOCK liveness event (``deadlock_events`` > 0)."""
    safe = sum(1 for r in ok if r.get("safety_verdict") not in ("unsafe", None, ""))
    success = sum(
        1 for r in ok
        if (r.get("mission_completed") is True if r.get("mission_completed") not in (None, "")
            else r.get("formation_time_s") not in (None, ""))
    )
    alarmed = sum(1 for r in ok if r.get("safety_verdict") not in ("safe", None, ""))
    stalled = sum(1 for r in ok if int(r.get("deadlock_events") or 0) > 0)
    return safe, success, alarmed, stalled


def clopper_pearson_lower(x: int, n: int, conf: float = CONFIDENCE) -> float:
    """One-sided lower confidence bound on a probability from ``x`` of ``n``: one minus
    :func:`clopper_pearson_upper` of the complement."""
    return 1.0 - clopper_pearson_upper(n - x, n, conf) if n > 0 else 0.0


def rates_table(rows: Sequence[Mapping[str, Any]], methods: list[str]) -> str:
    """Per scenario × method: the safety, success and alarm rates (:func:`run_rates`) with
    one-sided 95 % Clopper–Pearson bounds, and their two-sided 95 % Wilson intervals."""
    out = RATES_HEAD
    for scen in sorted({r["scenario"] for r in rows}):
        for m in methods:
            ok = [r for r in rows if r["scenario"] == scen and r["method"] == m
                  and r["status"] == "ok"]
            if not ok:
                continue
            n = len(ok)
            safe, success, alarmed, stalled = run_rates(ok)
            out += (
                f"| {scen} | {m} | {n} | {safe}/{n} ({clopper_pearson_lower(safe, n):.3f}) "
                f"| {success}/{n} ({clopper_pearson_lower(success, n):.3f}) "
                f"| {alarmed}/{n} ({clopper_pearson_upper(alarmed, n):.3f}) "
                f"| {stalled}/{n} | {_wilson_cell(safe, n)} | {_wilson_cell(success, n)} "
                f"| {_wilson_cell(alarmed, n)} |\n"
            )
    return out


def _stat(values: list[float], q: float) -> str:
    return f"{np.percentile(values, q):.3f}" if values else "–"


def _kappa(vertical_scale: float) -> str:
    """The clause naming κ of a barrier taller than wide (docs/safety.md §4c); empty for 1."""
    return f" κ = {vertical_scale:g}," if vertical_scale != 1.0 else ""


def summary_markdown(
    rows: Sequence[Mapping[str, Any]], specs: Mapping[str, Scenario], methods: list[str],
    wall_s: float,
) -> str:
    """``summary.md``: the table, the scenarios' τ and D, the crashed runs and a legend."""
    seeds = sorted({int(r["seed"]) for r in rows})
    lines = [
        "# Seed sweep",
        "",
        f"{len(rows)} in-process runs ({len(seeds)} seeds: {seeds[0]}–{seeds[-1]}) in "
        f"{wall_s:.0f} s wall time. Per-run rows: runs.csv. Definitions: docs/metrics.md.",
        "",
        summary_table(rows, methods),
        "Barrier parameters: "
        + "; ".join(f"{n}: τ = {sc.controller.tau_safe_s:g} s, D = {sc.controller.d_safe_m:g} m,"
                    + _kappa(sc.controller.dcbf_vertical_scale)
                    + f" formation deadline {sc.run.formation_deadline_s:g} s"
                    for n, sc in sorted(specs.items())) + ".",
        "",
        "* **Min dist p0 / p5 / p50**: percentiles over the runs (linear interpolation) of each "
        "run's smallest distance between any two vehicles, over the physics steps.",
        "* **True h_min**: the same percentiles of each run's smallest true barrier "
        "h = ‖Δp‖² + 2τ ΔvᵀΔp − D² over all pairs and control steps.",
        "* **Runs with h<0**: runs in which the true barrier of some pair went negative at "
        "least once; **Steps h<0**: control steps with some negative pair, summed over runs.",
        f"* **P(violation) 95 % UB**: one-sided {CONFIDENCE:.0%} Clopper–Pearson upper bound on "
        "the probability that a run has a barrier violation (with 0 of n: 1 − 0.05^(1/n) ≈ 3/n); "
        "**P(collision)** the same for runs with a contact.",
        "",
    ]
    lines += [
        "## Safety, success and alarm rates",
        "",
        rates_table(rows, methods),
        "* **Safe**: runs whose safety verdict is not \"unsafe\" (true barrier ≥ 0 at every "
        "step, no contact, no ground strike); **Success**: the formation formed, or the "
        "mission completed; **Alarmed**: runs whose verdict is not \"safe\" (a safety event of "
        "the truth, or an agent's own barrier below 0 or a safety alarm it raised); "
        "**Stalled**: runs in which an agent raised the DEADLOCK liveness event (its "
        "formation error stalled under the filter for 6 s). In brackets the one-sided "
        f"{CONFIDENCE:.0%} Clopper–Pearson bound: lower for the first two, upper for the last. "
        "**95 % CI**: the two-sided Wilson score interval of the same rate, the p with "
        "|x/n − p| ≤ 1.96 √(p(1 − p)/n).",
        "",
    ]
    missions = mission_table(rows, methods)
    if missions is not None:
        lines += [
            "## Formation missions",
            "",
            missions,
            "* **Completed**: runs whose formation centroid reached every waypoint in order "
            "(docs/missions.md); **P(not completed) 95 % UB** the Clopper–Pearson bound on the "
            "probability that a run does not. **Transit**: each run's formation error over the "
            "fixed transit window, p50 and max of the runs' rms, and the largest single error. "
            "**Observer error**: the largest desired-state observer error of any run.",
            "",
        ]
    crashed = [r for r in rows if r["status"] != "ok"]
    if crashed:
        lines += ["## Crashed runs", ""]
        lines += [f"* {r['scenario']} {r['method']} seed {r['seed']}: {r['error']}"
                  for r in crashed]
        lines.append("")
    lines += ["![summary](summary.png)", ""]
    return "\n".join(lines)


def plot_summary(
    rows: Sequence[Mapping[str, Any]], specs: Mapping[str, Scenario], methods: list[str], path: Path
) -> None:
    """Per scenario: min distance and true h_min of every run, one column of dots per
    method (the D_safe line and h = 0 dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scens = sorted({r["scenario"] for r in rows})
    fig, axes = plt.subplots(2, len(scens), figsize=(4.5 * len(scens), 6.5), squeeze=False)
    for c, scen in enumerate(scens):
        for r_i, (key, label) in enumerate((("min_distance_m", "min distance (m)"),
                                            ("h_min", "true h_min (m²)"))):
            ax = axes[r_i, c]
            for k, m in enumerate(methods):
                vals = [float(r[key]) for r in rows if r["scenario"] == scen
                        and r["method"] == m and r["status"] == "ok" and r.get(key) is not None]
                jitter = np.linspace(-0.15, 0.15, len(vals)) if len(vals) > 1 else [0.0]
                ax.scatter(np.asarray(jitter[: len(vals)]) + k, vals, s=10, color=f"C{k}")
            ref = 0.0 if key == "h_min" else specs[scen].controller.d_safe_m
            ax.axhline(ref, color="r", ls="--", lw=0.8)
            ax.set_xticks(range(len(methods)), methods)
            ax.set(ylabel=label, title=scen if r_i == 0 else "")
            ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(
    out: Path, rows: list[dict[str, Any]], specs: Mapping[str, Scenario], methods: list[str],
    wall_s: float,
) -> None:
    """``runs.csv``, ``summary.md`` and ``summary.png`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "runs.csv", rows)
    (out / "summary.md").write_text(summary_markdown(rows, specs, methods, wall_s))
    plot_summary(rows, specs, methods, out / "summary.png")

