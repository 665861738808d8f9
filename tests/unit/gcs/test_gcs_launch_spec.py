"""gcs.mission.launch_spec.LaunchSpec: one source for the ports and command lines of a swarm."""

from __future__ import annotations

from pathlib import Path

import pytest

from gcs.dashboard.launch import dashboard_spec
from gcs.mission.launch_spec import LaunchSpec
from swarm_common.scenario.model import load_scenario
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT

CUBE8 = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"


@pytest.fixture(scope="module")
def sc():
    return load_scenario(CUBE8)


def opt(argv: list[str], flag: str) -> str | None:
    return argv[argv.index(flag) + 1] if flag in argv else None


def test_mission_spec_is_lockstep_with_run_files(sc, tmp_path: Path) -> None:
    spec = LaunchSpec(sc, 3000, method="apf", seed=7, run_dir=tmp_path, sim_duration=11.0)
    assert spec.router_endpoint == f"tcp/127.0.0.1:{DEFAULT_ZENOH_PORT + 3000}"
    assert spec.sim_endpoint == f"tcp/127.0.0.1:{DEFAULT_ZENOH_PORT + 3001}"
    sim = spec.sim_argv()
    assert "--lockstep" in sim and opt(sim, "--step-timeout") == "1.0"
    assert opt(sim, "--zenoh-listen") == spec.sim_endpoint
    assert opt(sim, "--zenoh-connect") == spec.router_endpoint
    assert opt(sim, "--duration") == "11.0" and opt(sim, "--seed") == "7"
    assert opt(sim, "--stats-out") == str(tmp_path / "vehicle-sim-stats.json")
    d = spec.daemon_argv(3)
    assert opt(d, "--agent") == "3" and opt(d, "--port-offset") == "3000"
    assert opt(d, "--method") == "apf" and opt(d, "--seed") == "7"
    assert opt(d, "--tlog") == str(tmp_path / "vehicle_3.tlog")
    assert opt(d, "--swarm") == sc.name and opt(d, "--zenoh-connect") == spec.router_endpoint
    assert "--realtime" not in d and "--manual-start" not in d
    names = [name for name, _ in spec.processes()]
    assert names == ["vehicle-sim", *(f"offboard-{i}" for i in sc.ids)]


def test_dashboard_spec_is_real_time_manual_start(sc) -> None:
    spec = dashboard_spec(sc, 0, "blue", zenoh=True, method=None)
    sim = spec.sim_argv()
    assert "--lockstep" not in sim and "--step-timeout" not in sim and "--duration" not in sim
    assert opt(sim, "--swarm") == "blue"
    d = spec.daemon_argv(1)
    assert "--realtime" in d and "--manual-start" in d
    assert "--method" not in d and "--tlog" not in d and "--seed" not in d
    assert [n for n, _ in spec.processes(daemons=False)] == ["vehicle-sim"]


def test_without_zenoh_only_the_simulator_runs(sc) -> None:
    spec = dashboard_spec(sc, 0, None, zenoh=False, method="rcbf")
    procs = spec.processes()
    assert len(procs) == 1 and "--no-zenoh" in procs[0][1]
    assert "--zenoh-connect" not in procs[0][1]
