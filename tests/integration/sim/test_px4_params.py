"""The PX4 parameter protocol of vehicle-sim over loopback UDP, with unmodified clients:
MAVSDK's ``param`` and ``action`` plugins, pymavlink's own ``param_fetch_all`` (what
MAVProxy's ``param fetch`` sends), and the ``--params-file`` / port map of the command line.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, free_port_offset, wait_for
from mavsdk_client import mavsdk_autopilot
from pymavlink.dialects.v20 import common as M

from swarm_common.ports import vehicle_ports
from swarm_common.scenario.model import load_scenario
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.autopilot.params import FILE_FORMAT, INT32
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.param import int32_to_wire, wire_to_int32
from vehicle_sim.vehicle import Vehicle

ONE = ["--no-zenoh", "--vehicles", "1"]


def _table(agent_id: int = 1) -> Vehicle:
    """An in-process vehicle of the same scenario: the table the simulator exposes."""
    dyn = SwarmDynamics(load_scenario(CUBE8), held=True)
    return Vehicle(agent_id, agent_id - 1, dyn, AutopilotConfig())


@pytest.fixture
def mavsdk_system(sim_factory):
    """(sim, mavsdk module, system) of an unmodified MAVSDK on vehicle 1's API link."""
    sim = sim_factory(ONE)
    with mavsdk_autopilot(sim) as system:
        yield sim, system


def test_mavsdk_param_get_set_all(mavsdk_system) -> None:
    from mavsdk.plugins.param import Param

    _sim, system = mavsdk_system
    par = Param(system)
    ref = _table().params
    assert par.get_param_float("MPC_THR_HOVER") == pytest.approx(ref.get("MPC_THR_HOVER"))
    assert par.get_param_int("MAV_SYS_ID") == 1
    assert par.get_param_int("COM_OBL_RC_ACT") == ref.get("COM_OBL_RC_ACT")
    par.set_param_float("MPC_THR_HOVER", 0.45)
    assert par.get_param_float("MPC_THR_HOVER") == pytest.approx(0.45)
    par.set_param_int("COM_OBL_RC_ACT", 4)
    assert par.get_param_int("COM_OBL_RC_ACT") == 4

    allp = par.get_all_params()
    got = {p.name: p.value for p in allp.int_params + allp.float_params}
    assert len(got) == len(ref)
    for s in ref.specs:
        want = {"MPC_THR_HOVER": 0.45, "COM_OBL_RC_ACT": 4}.get(s.name, ref.get(s.name))
        if s.ptype == INT32:
            assert got[s.name] == want, s.name
        else:
            assert got[s.name] == pytest.approx(want, rel=1e-6), s.name


def test_mavsdk_takeoff_altitude_is_mis_takeoff_alt(mavsdk_system) -> None:
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.param import Param

    _sim, system = mavsdk_system
    act, par = Action(system), Param(system)
    act.set_takeoff_altitude(7.5)
    assert act.get_takeoff_altitude() == pytest.approx(7.5)
    assert par.get_param_float("MIS_TAKEOFF_ALT") == pytest.approx(7.5)


def test_mavsdk_bad_name_and_value_are_errors_not_timeouts(mavsdk_system) -> None:
    from mavsdk.plugins.param import Param, ParamError, ParamResult

    sim, system = mavsdk_system
    par = Param(system)
    cases = [
        (lambda: par.get_param_float("NO_SUCH_PARAM"), ParamResult.DOES_NOT_EXIST),
        (lambda: par.set_param_float("NO_SUCH_PARAM", 1.0), ParamResult.DOES_NOT_EXIST),
        (lambda: par.set_param_float("MPC_THR_HOVER", 5.0), ParamResult.VALUE_OUT_OF_RANGE),
        (lambda: par.set_param_int("MAV_SYS_ID", 7), ParamResult.READ_ONLY),
    ]
    for call, result in cases:
        with pytest.raises(ParamError) as ei:
            call()
        assert ei.value.result == result
    assert par.get_param_float("MPC_THR_HOVER") == pytest.approx(
        _table().params.get("MPC_THR_HOVER")
    )
    assert sim.wait_log(r"vehicle 1: param: MPC_THR_HOVER = 5 outside") is not None


@pytest.mark.parametrize("clock", [[], ["--lockstep"]], ids=["real-time", "lockstep"])
def test_pymavlink_param_fetch_all_completes_once_per_index(sim_factory, mav_client, clock):
    """What MAVProxy's ``param fetch`` does: PARAM_REQUEST_LIST, then PARAM_VALUE until
    every index of ``param_count`` has come (on the GCS link, as a GCS would); in lockstep
    too, where simulated time stands still until a controller answers."""
    sim = sim_factory(ONE + clock)
    c = mav_client(vehicle_ports(1, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10.0, sysid=1) is not None
    c.conn.target_system, c.conn.target_component = 1, 1
    c.conn.param_fetch_all()
    seen: dict[int, str] = {}
    count = None
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and (count is None or len(seen) < count):
        m = c.recv("PARAM_VALUE", 1.0, sysid=1)
        if m is None:
            continue
        assert m.param_index not in seen, f"index {m.param_index} twice"
        assert count in (None, m.param_count)
        count = m.param_count
        seen[m.param_index] = m.param_id
    n = len(_table().params)
    assert count == n and sorted(seen) == list(range(n))
    assert seen[_table().params.index["MAV_SYS_ID"]] == "MAV_SYS_ID"
    assert c.conn.params["MPC_THR_HOVER"] == pytest.approx(_table().params.get("MPC_THR_HOVER"))


def test_pymavlink_read_by_index_and_int32_set(sim_factory, mav_client) -> None:
    sim = sim_factory(ONE)
    c = mav_client(vehicle_ports(1, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10.0, sysid=1) is not None
    i = _table().params.index["GF_ACTION"]
    c.mav.param_request_read_send(1, 1, b"", i)
    m = c.recv("PARAM_VALUE", 3.0, sysid=1, cond=lambda m: m.param_index == i)
    assert m is not None and m.param_id == "GF_ACTION" and m.param_type == INT32
    c.mav.param_set_send(1, 1, b"GF_ACTION", int32_to_wire(2), INT32)
    m = c.recv("PARAM_VALUE", 3.0, sysid=1, cond=lambda m: m.param_id == "GF_ACTION")
    assert m is not None and wire_to_int32(m.param_value) == 2
    c.mav.param_set_send(1, 1, b"GF_ACTION", int32_to_wire(9), INT32)
    e = c.recv("PARAM_ERROR", 3.0, sysid=1)
    assert e is not None and e.error == M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE


def test_params_file_loaded_and_saved_per_vehicle(sim_factory, mav_client, tmp_path) -> None:
    path = tmp_path / "params.json"
    doc = {"format": FILE_FORMAT, "vehicles": {"2": {"MPC_THR_HOVER": 0.4}, "7": {"GF_ACTION": 3}}}
    path.write_text(json.dumps(doc))
    sim = sim_factory(["--no-zenoh", "--vehicles", "2", "--params-file", str(path)])
    c = mav_client(vehicle_ports(2, sim.offset).gcs_remote)
    assert c.recv("HEARTBEAT", 10.0, sysid=2) is not None
    c.mav.param_request_read_send(2, 1, b"MPC_THR_HOVER", -1)
    m = c.recv("PARAM_VALUE", 3.0, sysid=2, cond=lambda m: m.param_id == "MPC_THR_HOVER")
    assert m is not None and m.param_value == pytest.approx(0.4)
    c.mav.param_set_send(2, 1, b"COM_OF_LOSS_T", 1.5, M.MAV_PARAM_TYPE_REAL32)
    assert c.recv("PARAM_VALUE", 3.0, sysid=2, cond=lambda m: m.param_id == "COM_OF_LOSS_T")

    def saved() -> dict:
        return json.loads(path.read_text())["vehicles"]

    assert wait_for(lambda: "COM_OF_LOSS_T" in saved().get("2", {}), 3.0)
    assert saved() == {
        "2": {"MPC_THR_HOVER": 0.4, "COM_OF_LOSS_T": 1.5},
        "7": {"GF_ACTION": 3},  # not in this run: kept
    }
    assert sim.wait_log(r"parameters: .*params\.json") is not None


@pytest.mark.parametrize(
    ("content", "words"),
    [
        ("{", "not JSON"),
        (json.dumps({"format": FILE_FORMAT, "vehicles": {"1": {"NOPE": 1}}}), "unknown"),
        (json.dumps({"format": FILE_FORMAT, "vehicles": {"1": {"MPC_THR_HOVER": 3}}}), "outside"),
    ],
)
def test_bad_params_file_exits_2_with_one_line(tmp_path: Path, content: str, words: str) -> None:
    path = tmp_path / "p.json"
    path.write_text(content)
    r = subprocess.run(
        [*[sys.executable, "-m", "vehicle_sim.cli"], "--scenario", CUBE8, *ONE,
         "--port-offset", str(free_port_offset()), "--params-file", str(path), "--duration", "0.1"],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and "--params-file" in lines[0] and words in lines[0], r.stderr


def test_startup_prints_the_port_map(sim_factory) -> None:
    sim = sim_factory(["--vehicles", "2"])
    for aid in (1, 2):
        p = vehicle_ports(aid, sim.offset)
        line = sim.wait_log(rf"vehicle {aid} \(sysid {aid}\): API/offboard")
        assert line is not None
        assert f":{p.api_local} -> 127.0.0.1:{p.api_remote}" in line
        assert f":{p.gcs_local} -> 127.0.0.1:{p.gcs_remote}" in line
    z = sim.wait_log(r"zenoh \(peer\): listen tcp/127\.0\.0\.1:")
    assert z is not None and str(7447 + sim.offset) in z
