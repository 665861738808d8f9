"""Link latency in process (``communication.delay_s``, docs/faults.md): the neighbours'
estimates reach every agent the scenario's latency late, rounded up to the next control
step; no latency leaves the run as it was; distributed runs and daemons refuse the key."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import CUBE8, ROOT

from gcs.mission.distributed import run_distributed
from gcs.mission.inproc import run_inproc
from gcs.mission.launch_spec import LaunchError
from offboard.agent.follower import FollowerAgent
from swarm_common.scenario.files import ScenarioError, dump_toml
from swarm_common.scenario.model import load_scenario, with_overrides

SC = load_scenario(CUBE8)


@pytest.mark.parametrize(("delay", "periods"), [(0.0, 0), (0.02, 0), (0.021, 1), (0.05, 2),
                                                 (0.2, 9)])
def test_a_latency_is_rounded_up_to_the_next_step(delay: float, periods: int) -> None:
    assert with_overrides(SC, communication={"delay_s": delay}).delay_periods == periods


def test_a_latency_longer_than_the_data_may_age_is_refused() -> None:
    with pytest.raises(ScenarioError, match="communication.delay_s = 1.0: must be below"):
        with_overrides(SC, communication={"delay_s": 1.0})


def test_every_agent_hears_its_neighbours_late(monkeypatch: pytest.MonkeyPatch) -> None:
    """The newest stamp a follower receives at t_k is t_k − d·dt (d extra periods), and the
    run with a latency differs from the one without."""
    sc = with_overrides(SC, communication={"delay_s": 0.1})  # 4 extra periods of 20 ms
    d, dt = sc.delay_periods, sc.control_dt
    seen: list[tuple[float, float]] = []
    step = FollowerAgent.step

    def spy(self, k, t, truth_p, truth_v, neighbours, comm_ok=True):  # type: ignore[no-untyped-def]
        if self.id == 3:
            seen.append((t, float(np.nanmax(neighbours.t))))
        return step(self, k, t, truth_p, truth_v, neighbours, comm_ok)

    monkeypatch.setattr(FollowerAgent, "step", spy)
    late = run_inproc(sc, "dcbf", seed=1, duration=1.0).metrics
    for t, newest in seen:
        if t >= (d + 1) * dt - 1e-12:
            assert newest == pytest.approx(t - d * dt, abs=1e-9)
        else:  # nothing published yet has arrived: the initial estimates (t = 0)
            assert newest == 0.0
    monkeypatch.setattr(FollowerAgent, "step", step)
    prompt = run_inproc(SC, "dcbf", seed=1, duration=1.0).metrics
    assert late["min_distance_m"] != prompt["min_distance_m"]


def test_distributed_runs_and_daemons_refuse_a_latency(tmp_path) -> None:
    sc = with_overrides(SC, communication={"delay_s": 0.1})
    with pytest.raises(LaunchError, match="in process only"):
        run_distributed(sc, tmp_path / "run", "dcbf", None, 1.0, show_progress=False)
    path = tmp_path / "late.toml"
    path.write_text(dump_toml(sc.to_toml_dict()))
    r = subprocess.run([sys.executable, "-m", "offboard", "--scenario", str(path), "--agent", "3"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "modelled in process only" in r.stderr
