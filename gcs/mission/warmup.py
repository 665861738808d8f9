"""Compile the control and simulation kernels once (numba, :mod:`swarm_common.jit`).

A kernel is compiled on its first call in a process and cached on disk, so only the first
process on a machine (or after a source change) pays for it, a few seconds in all. A
swarm started from a cold cache would have every daemon and the simulator compile the
same kernels at the same time; :func:`compile_kernels` does it once beforehand, by
flying a few control periods of cube8 in process with every safety method (the daemons
and ``vehicle-sim`` drive the same objects, so the same kernels and argument types), then
the simulator's own warm-up (:func:`vehicle_sim.server.load_kernels`: its telemetry).
The test suite calls it at session start.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from swarm_common.enums import Method
from swarm_common.scenario.model import load_scenario

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "cube8.toml"
PERIODS = 5  # control periods per method


def compile_kernels(scenario: Path = SCENARIO) -> float:
    """Fly ``PERIODS`` control periods of ``scenario`` in process per method; returns the
    wall time (s) it took (≈ 1 s with a warm cache)."""
    from gcs.mission.inproc import run_inproc
    from vehicle_sim.server import load_kernels

    t0 = time.perf_counter()
    sc = load_scenario(scenario)
    level = logging.getLogger().level
    # the runs' lines are noise here: their INFO, and the verdict of a few periods flown only
    # to compile (a scenario outside its assumptions warns of itself when it is loaded)
    logging.getLogger().setLevel(logging.ERROR)
    try:
        for method in Method:
            run_inproc(sc, method, duration=PERIODS * sc.control_dt)
        load_kernels(sc)  # the simulator's own (telemetry), not run in process
    finally:
        logging.getLogger().setLevel(level)
    return time.perf_counter() - t0
