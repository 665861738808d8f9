"""``offboard --sensing odometry``: the swarm flies without the simulator's truth
(docs/px4/offboard-component.md, "Sensing sources"). A short lockstep cube8 run with
``vehicle-sim --no-zenoh`` (no truth published at all) and eight daemons that build
their sensor inputs from their own and their neighbours' published odometry: no
collision, the formation error falls, and it ends close to (not identical with) the same
run sensed from truth. That run is flown in process: a lockstep run sensed from truth
equals it bit for bit (tests/integration/mission/test_mission_distributed.py)."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import CUBE8, free_port_offset, start_child, stop_processes

from gcs.mission.inproc import run_inproc
from gcs.mission.procs import python_entry
from swarm_common import wire
from swarm_common.scenario.model import load_scenario
from swarm_common.zenoh_session import default_endpoint, open_session

pytestmark = pytest.mark.timeout(400)

DURATION_S = 4.0


class Record:
    """Every daemon's published odometry and status, by (step, id)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.p: dict[tuple[int, int], np.ndarray] = {}
        self.p_des: dict[tuple[int, int], np.ndarray] = {}

    def on_sample(self, sample: Any) -> None:
        try:
            msg = wire.decode(sample.payload.to_bytes())
        except wire.WireError:
            return
        with self.lock:
            if isinstance(msg, wire.Odometry):
                self.p[(msg.step, msg.id)] = msg.p
            elif isinstance(msg, wire.Status):
                self.p_des[(msg.step, msg.id)] = msg.p_des

    def formation_error(self, ids: list[int]) -> dict[int, float]:
        """Mean over agents of |p_i − p*_i| (m), per step where every agent has both."""
        out: dict[int, float] = {}
        with self.lock:
            steps = sorted({k for k, _ in self.p_des})
            for k in steps:
                if all((k, i) in self.p and (k, i) in self.p_des for i in ids):
                    out[k] = float(np.mean([np.linalg.norm(self.p[(k, i)] - self.p_des[(k, i)])
                                            for i in ids]))
        return out


def _run(tmp: Path) -> tuple[dict[str, Any], dict[int, float], list[float]]:
    """One lockstep run sensed from odometry; (the simulator's stats, formation error per
    step, minimum pair distance per step from the published odometry)."""
    sensing = "odometry"
    sc = load_scenario(CUBE8)
    off = free_port_offset()
    router_ep = default_endpoint(off)
    stats = tmp / f"stats-{sensing}.json"
    rec = Record()
    router = open_session(mode="router", listen=[router_ep])
    subs = [router.declare_subscriber(wire.key_odometry(sc.name, "*"), rec.on_sample),
            router.declare_subscriber(wire.key_status(sc.name, "*"), rec.on_sample)]
    sim_args = [*python_entry("vehicle_sim.cli"), "--scenario", CUBE8,
                "--port-offset", str(off), "--lockstep", "--step-timeout", "1.0",
                "--duration", str(DURATION_S), "--stats-out", str(stats), "--quiet",
                "--no-zenoh"]  # no truth anywhere
    procs = [start_child(sim_args, tmp / f"{sensing}-sim.log")]
    for i in sc.ids:
        procs.append(start_child(
            [*python_entry("offboard.cli"), "--scenario", CUBE8, "--agent", str(i),
             "--port-offset", str(off), "--zenoh-connect", router_ep, "--sensing", sensing],
            tmp / f"{sensing}-{i}.log"))
    try:
        assert procs[0].wait(360) == 0
    finally:
        stop_processes(procs)
        for s in subs:
            s.undeclare()
        router.close()
    with rec.lock:
        steps = sorted({k for k, _ in rec.p})
        min_d = []
        for k in steps:
            pts = [rec.p[(k, i)] for i in sc.ids if (k, i) in rec.p]
            if len(pts) == len(sc.ids):
                a = np.array(pts)
                d = np.linalg.norm(a[:, None] - a[None], axis=2) + np.eye(len(pts)) * 1e9
                min_d.append(float(d.min()))
    return json.loads(stats.read_text()), rec.formation_error(list(sc.ids)), min_d


def _truth_run() -> dict[int, float]:
    """The same flight sensed from truth, in process: formation error per step, matched to
    the daemons' records (the status of step k carries the estimate for t_{k+1})."""
    sc = load_scenario(CUBE8)
    ser = run_inproc(sc, "dcbf", duration=DURATION_S).series
    err = np.linalg.norm(ser.p[:-1] - ser.xi_p[1:], axis=2).mean(axis=1)
    return {k: float(e) for k, e in enumerate(err)}


def test_swarm_flies_on_odometry_without_truth(tmp_path: Path) -> None:
    stats_o, err_o, min_o = _run(tmp_path)
    for f in sorted(tmp_path.glob("odometry-*.log")):
        print(f"--- {f.name}\n{f.read_text()[-1500:]}")
    assert stats_o["collisions"] == 0
    assert min_o and min(min_o) > 0.5
    steps = sorted(err_o)
    assert len(steps) > 50
    first, last = err_o[steps[0]], float(np.mean([err_o[k] for k in steps[-10:]]))
    print(f"odometry: formation error {first:.3f} m -> {last:.3f} m, min distance "
          f"{min(min_o):.2f} m")
    # converging: the truth-sourced run of the same 4 s goes 0.615 -> 0.336 m (0.55), so
    # the bar is "clearly falling", and the comparison with it below is the tight check
    assert last < 0.7 * first

    err_t = _truth_run()
    common = sorted(set(err_o) & set(err_t))
    assert len(common) > 50
    diff = [abs(err_o[k] - err_t[k]) for k in common]
    last_t = float(np.mean([err_t[k] for k in common[-10:]]))
    print(f"truth: final formation error {last_t:.3f} m; |odometry - truth| max "
          f"{max(diff):.4f} m")
    assert max(diff) > 0.0  # two sources: not the same numbers
    assert abs(last - last_t) < 0.1 + 0.2 * last_t  # but the same flight
