"""Physics steps per second of SwarmDynamics for the 8 vehicles of cube8 (no asserts).

    .venv/bin/python bench/bench_dynamics.py [--steps 20000]

Prints: raw dynamics steps/s, the real-time factor at the scenario's physics rate, and
the cost of one full simulator control step (8 state machines + commands + 4 physics
steps + Truth encoding), which is what bounds lockstep speed on the simulator side.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from swarm_common import wire
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.vehicle import Vehicle

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--steps", type=int, default=20000)
    a = ap.parse_args()
    sc = load_scenario(a.scenario)
    dyn = SwarmDynamics(sc)
    for i in range(dyn.n):
        dyn.set_command(i, 0.05, -0.05, 0.0, dyn.hold_thrust() * 1.01)
    dyn.advance(100)
    t0 = time.perf_counter()
    dyn.advance(a.steps)
    el = time.perf_counter() - t0
    rate = a.steps / el
    phys_hz = 1.0 / sc.physics_dt
    print(f"vehicles: {dyn.n}, physics {phys_hz:.0f} Hz, control {1 / sc.control_dt:.0f} Hz")
    print(f"dynamics: {rate:,.0f} physics steps/s ({1e6 / rate:.1f} us/step), "
          f"real-time factor {rate / phys_hz:.1f}x")  # fmt: skip

    # a full control step as the server runs it (without sockets)
    dyn = SwarmDynamics(sc, held=False)
    veh = [Vehicle(aid, i, dyn, AutopilotConfig()) for i, aid in enumerate(sc.ids)]
    for v in veh:
        v.arm(0.0)
    n = max(500, a.steps // 10)
    t0 = time.perf_counter()
    for k in range(n):
        t = k * sc.control_dt
        for v in veh:
            v.update(t)
            dyn.set_command(v.idx, *v.command(sc.control_dt))
        dyn.advance(sc.substeps_per_control)
        tr = wire.Truth(k, t, sc.ids, dyn.p, dyn.v, dyn.att, dyn.thrust, dyn.lumped_accel(),
                        [True] * dyn.n, ["HOLD"] * dyn.n, dyn.collisions)  # fmt: skip
        wire.encode(tr)
        for v in veh:
            v.pack(v.odometry(t))
    el = time.perf_counter() - t0
    print(f"server control step (8 vehicles, hold controllers, {sc.substeps_per_control} "
          f"physics steps, Truth + 8 ODOMETRY encoded): {1e6 * el / n:.0f} us/step, "
          f"{n / el:,.0f} control steps/s = {n / el * sc.control_dt:.1f}x real time")  # fmt: skip


if __name__ == "__main__":
    main()
