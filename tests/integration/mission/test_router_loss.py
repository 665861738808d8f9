"""The router dies, or stalls, in the middle of a real-time mission (docs/security.md,
"Losing the runner or the router"), with the product's processes (tests/realtime_swarm.py).
Killed: every daemon brakes and holds, then lands its vehicle on its slot of the
coordinated landing plan from its own ODOMETRY, and disarms it. Stopped for 0.4 s: every
daemon brakes and holds, then flies on."""

from __future__ import annotations

import re
import signal
import time
from pathlib import Path

import pytest
from realtime_swarm import collisions, flying_swarm, wait_for

pytestmark = pytest.mark.timeout(240)

MIN_DIST_M = 0.5
FLY_BEFORE_KILL_S = 8.0  # mission time at which the router is killed
LAND_TIMEOUT_S = 90.0  # wall s after the kill (landing ≈ 3 s hold + 13 s on a loaded host)
PLAN_LINE = re.compile(r"runner/router lost since t=([\d.]+) s: landing on odometry, "
                       r"t_L=([\d.]+) s")


@pytest.mark.slow
def test_router_kill_lands_every_vehicle_safely(tmp_path: Path) -> None:
    with flying_swarm(tmp_path, FLY_BEFORE_KILL_S) as sw:
        obs = sw.obs
        before, before_at = obs.reset_min()
        sw.router.send_signal(signal.SIGKILL)
        sw.router.wait(10)
        t_kill = obs.time_s()
        wait_for(obs.landed, LAND_TIMEOUT_S, "every vehicle landed and disarmed")
        t_landed = obs.time_s()
        assert all(p.poll() is None for p in sw.procs), "a process died"
    assert collisions(tmp_path) == 0
    assert obs.samples > 100 and obs.min_dist >= MIN_DIST_M, obs.min_dist
    plans = [PLAN_LINE.search(p.read_text()) for p in sw.logs]
    assert all(plans), [p.name for p, m in zip(sw.logs, plans, strict=True) if m is None]
    t_l = [float(m.group(2)) for m in plans if m is not None]
    assert max(t_l) - min(t_l) <= 0.5  # one land time (within a few steps), no communication
    print(f"router killed at t={t_kill:.2f} s, t_L={min(t_l):.2f}..{max(t_l):.2f} s, all "
          f"landed and disarmed by t={t_landed:.2f} s; min distance {obs.min_dist:.3f} m "
          f"over {obs.samples} snapshots after the kill ({before:.3f} m at t={before_at:.2f} s "
          "before it); collisions 0")


STALL_S = 0.4  # wall s the router is stopped: past the stall threshold, short of the loss


def test_router_stall_brakes_then_flies_on(tmp_path: Path) -> None:
    """SIGSTOP of the router for 0.4 s (truth 10–25 periods late on every daemon): each
    daemon brakes to a hold on its own odometry, then flies on when truth is back; nobody
    lands, nobody collides, and the formation flies on well apart."""
    with flying_swarm(tmp_path, FLY_BEFORE_KILL_S) as sw:
        obs = sw.obs
        sw.router.send_signal(signal.SIGSTOP)
        time.sleep(STALL_S)
        sw.router.send_signal(signal.SIGCONT)
        t_stall = obs.time_s()
        wait_for(lambda: all("truth back" in p.read_text() for p in sw.logs), 30,
              "every daemon to fly on")
        wait_for(lambda: obs.time_s() >= t_stall + 4.0, 60, "4 s more of flight")
        assert all(p.poll() is None for p in sw.procs), "a process died"
        assert all(obs.armed.get(i) for i in obs.ids)
    texts = [p.read_text() for p in sw.logs]
    assert all("braking to a hold" in t for t in texts)
    assert not any("landing on odometry" in t for t in texts)
    assert collisions(tmp_path) == 0
    assert obs.samples > 100 and obs.min_dist >= MIN_DIST_M, obs.min_dist
    print(f"router stopped {STALL_S} s at t={t_stall:.2f} s: every daemon braked and flew "
          f"on; min distance {obs.min_dist:.3f} m over {obs.samples} snapshots")
