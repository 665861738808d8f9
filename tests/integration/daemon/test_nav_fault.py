"""A follower's navigation check fails in a real-time flight, with the product's processes
(tests/realtime_swarm.py; docs/faults.md, "A starved daemon").

Nothing in the fault injection corrupts an estimate, so the check is made to fail the
honest way: agent 5's daemon runs with a 1 mm gate (``offboard --nav-gate 0.001``), which
a DESO estimate built from bearings in flight never stays within. That daemon must declare
a navigation fault, hold on its vehicle's odometry, land it on its slot of the landing plan
and disarm it, for good, while the other seven fly on, armed, with the default 2 m gate
never failing, and no two vehicles come closer than 0.5 m."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from realtime_swarm import collisions, flying_swarm, wait_for

pytestmark = pytest.mark.timeout(240)

FAULTY = 5  # a follower of cube8
GATE_M = 0.001
MIN_DIST_M = 0.5
FLY_S = 0.5  # mission time before the test starts watching (the fault comes early)
LAND_TIMEOUT_S = 90.0  # wall s for the faulty vehicle to land and disarm (loaded host)
FLY_ON_S = 6.0  # mission s the others must fly on after that landing
FAULT_LINE = re.compile(r"agent (\d+): estimate off its odometry by more than ([\d.e-]+) m at "
                        r"t=([\d.]+) s: holding on odometry; landing at t=([\d.]+) s")


@pytest.mark.slow
def test_a_navigation_fault_lands_its_vehicle_and_the_swarm_flies_on(tmp_path: Path) -> None:
    extra = {FAULTY: ["--nav-gate", str(GATE_M)]}
    with flying_swarm(tmp_path, FLY_S, extra_args=extra, all_armed=False) as sw:
        obs = sw.obs
        others = [i for i in obs.ids if i != FAULTY]
        wait_for(lambda: obs.landed_one(FAULTY), LAND_TIMEOUT_S,
                 f"vehicle {FAULTY} landed and disarmed")
        t_landed = obs.time_s()
        wait_for(lambda: obs.time_s() >= t_landed + FLY_ON_S, 60, "the others to fly on")
        assert all(obs.armed.get(i) for i in others), obs.armed
        assert obs.landed_one(FAULTY), "the faulty vehicle stays down: no way back"
        assert all(p.poll() is None for p in sw.procs), "a process died"
        texts = {int(p.stem.removeprefix("offboard-")): p.read_text() for p in sw.logs}
    faults = {i: FAULT_LINE.search(t) for i, t in texts.items()}
    assert [i for i, m in faults.items() if m] == [FAULTY], faults
    m = faults[FAULTY]
    assert m is not None and float(m.group(2)) == GATE_M
    t_fault, t_land = float(m.group(3)), float(m.group(4))
    assert t_land == pytest.approx(t_fault + 3.0, abs=0.05)  # --loss-land-after's default
    assert collisions(tmp_path) == 0
    assert obs.samples > 100 and obs.min_dist >= MIN_DIST_M, obs.min_dist
    print(f"agent {FAULTY}: navigation fault at t={t_fault:.2f} s, landing at t={t_land:.2f} "
          f"s, landed and disarmed by t={t_landed:.2f} s; the other {len(others)} flew on; "
          f"min distance {obs.min_dist:.3f} m over {obs.samples} snapshots; collisions 0")
