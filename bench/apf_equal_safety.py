"""Energy at equal safety: the APF tuned until its min distance is >= D_safe on cube8,
against RCBF, DCBF and no avoidance (issue "safety", item 8).

    .venv/bin/python bench/apf_equal_safety.py [--seeds 1-10] [--duration 60] [--jobs 2]

Prints, per method, the worst and median min distance over the seeds, the collisions and
the medians of E_u = integral of sum ||u||^2 dt and E_F = integral of sum (F - m g)^2 dt
(docs/metrics.md). The tuned APF gains are the ``TUNED_APF`` overrides below
(docs/paper-mapping.md explains how they were found).
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from gcs.mission.inproc import run_inproc
from swarm_common.scenario.model import load_scenario, with_overrides

SCENARIO = "scenarios/cube8.toml"
TUNED_APF = {"apf_gain": 16.0, "apf_velocity_gain": 16.0, "apf_radius_m": 3.0}
VARIANTS: dict[str, tuple[str, dict[str, float]]] = {
    "rcbf": ("rcbf", {}),
    "dcbf": ("dcbf", {}),
    "apf (paper-like gains)": ("apf", {}),
    "apf (tuned)": ("apf", TUNED_APF),
    "none": ("none", {}),
}


def _one(job: tuple[str, int, float]) -> tuple[str, int, dict[str, Any]]:
    name, seed, duration = job
    method, overrides = VARIANTS[name]
    sc = load_scenario(SCENARIO)
    if overrides:
        sc = with_overrides(sc, controller=overrides)
    res = run_inproc(sc, method=method, seed=seed, duration=duration)
    return name, seed, res.metrics


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-10")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    jobs = [(name, s, args.duration) for name in VARIANTS for s in _seeds(args.seeds)]
    rows: dict[str, list[dict[str, Any]]] = {name: [] for name in VARIANTS}
    with ProcessPoolExecutor(args.jobs) as ex:
        for name, _seed, m in ex.map(_one, jobs):
            rows[name].append(m)
    print(f"cube8, seeds {args.seeds}, {args.duration:g} s")
    print("| method | min distance worst / median (m) | collisions (sum) | h_min worst (m^2) "
          "| E_u median (m^2/s^3) | E_F median (N^2 s) |")
    print("|---|---|---|---|---|---|")
    for name, ms in rows.items():
        md = np.array([m["min_distance_m"] for m in ms])
        print(
            f"| {name} | {md.min():.3f} / {np.median(md):.3f} | "
            f"{sum(int(m['collisions']) for m in ms)} | "
            f"{min(float(m['h_min']) for m in ms):.3f} | "
            f"{np.median([m['energy_u'] for m in ms]):.0f} | "
            f"{np.median([m['energy_thrust_excess'] for m in ms]):.0f} |"
        )


if __name__ == "__main__":
    main()
