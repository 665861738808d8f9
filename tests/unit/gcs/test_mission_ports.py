"""The port probe of a launch (gcs.mission.ports): which ports a swarm binds, a busy one
named in one line, the first free offset, and the cause of a child's early exit."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from conftest import HeldPorts

from gcs.mission.launch_spec import LaunchError, LaunchSpec
from gcs.mission.ports import (
    PortUse,
    bind_failure_line,
    choose_port_offset,
    port_in_use_line,
    swarm_port_uses,
)
from gcs.mission.preflight import resolve_port_offset
from gcs.mission.procs import ProcessGroup, cause_line
from gcs.mission.supervise import MissionError, early_death
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]
CUBE8 = str(ROOT / "scenarios" / "cube8.toml")
# below every offset the test sessions' pool gives (multiples of 1000 and 300 above one),
# and its ports far below the ephemeral range: no other test binds these
BASE = 537


def _free_block(start: int, ids: list[int], blocks: int) -> int:
    """The first offset start + k·1000 whose next ``blocks`` blocks of ports are all free
    now (the machine is shared with other work)."""
    for k in range(12):
        off = start + 1000 * k
        offs = [off + 1000 * b for b in range(blocks)]
        if all(u.free() for o in offs for u in swarm_port_uses(ids, o)):
            return off
    pytest.skip("no free block of ports near the test offsets")


def test_every_port_of_a_swarm_is_listed_with_its_protocol_and_role() -> None:
    uses = swarm_port_uses([1, 2, 11], 100)
    got = {(u.proto, u.port): u.role for u in uses}
    assert got == {
        ("TCP", 7547): "Zenoh router", ("TCP", 7548): "Zenoh simulator",
        ("UDP", 14680): "vehicle 1 simulator API port",
        ("UDP", 18670): "vehicle 1 simulator GCS port",
        ("UDP", 14681): "vehicle 2 simulator API port",
        ("UDP", 18671): "vehicle 2 simulator GCS port",
        ("UDP", 14690): "vehicle 11 simulator API port",
        ("UDP", 18680): "vehicle 11 simulator GCS port",
        ("UDP", 14640): "agent 1 API port", ("UDP", 14641): "agent 2 API port",
        ("UDP", 15100): "agent 11 API port",
    }
    assert len(uses) == len(got)  # no port twice
    extra = {u.port for u in swarm_port_uses([1], 100, gcs_port=True, formation_port=14660)}
    assert {14650, 14660} <= extra


def test_a_busy_port_is_named_in_one_line(held_ports: HeldPorts) -> None:
    off = _free_block(BASE, [1, 2], 1)
    assert held_ports.udp(14540 + off)
    assert held_ports.tcp(7447 + off)
    busy = [u for u in swarm_port_uses([1, 2], off) if not u.free()]
    assert [(u.proto, u.port) for u in busy] == [("TCP", 7447 + off), ("UDP", 14540 + off)]
    line = port_in_use_line(busy[1:])
    assert line.startswith(f"udp {14540 + off} (127.0.0.1, agent 1 API port) is in use;")
    assert "--port-offset" in line and "\n" not in line
    assert "(and 1 more)" in port_in_use_line(busy)


def test_the_first_offset_with_every_port_free_is_chosen(held_ports: HeldPorts) -> None:
    off = _free_block(BASE, [1, 2], 3)
    assert choose_port_offset([1, 2], 40000, start=off) == off
    assert held_ports.udp(14541 + off)  # agent 2's API port at the first offset
    assert choose_port_offset([1, 2], 40000, start=off) == off + 1000
    assert held_ports.tcp(7448 + off + 1000)  # the simulator's Zenoh port at the second
    assert choose_port_offset([1, 2], 40000, start=off) == off + 2000
    assert choose_port_offset([1, 2], off + 1999, start=off) is None  # none left below
    held_ports.release(0)
    assert choose_port_offset([1, 2], 40000, start=off) == off  # released: free again


def test_a_forced_offset_fails_on_a_busy_port_and_none_chooses(held_ports: HeldPorts) -> None:
    sc = load_scenario(CUBE8)
    off = _free_block(BASE, list(sc.ids), 1)
    assert resolve_port_offset(sc, off) == off
    assert held_ports.udp(14580 + 7 + off)  # vehicle 8's simulator API port
    with pytest.raises(LaunchError, match=rf"^udp {14587 + off} \(127\.0\.0\.1, vehicle 8 "):
        resolve_port_offset(sc, off)
    spec = LaunchSpec(sc, off)
    assert spec.busy_ports() == [f"udp {14587 + off} (127.0.0.1, vehicle 8 simulator API port)"]
    held_ports.release()
    assert held_ports.udp(14560 + off)  # the formation vehicle's port: busy only when it is served
    assert resolve_port_offset(sc, off) == off
    with pytest.raises(LaunchError, match="formation vehicle"):
        resolve_port_offset(sc, off, formation_base=14560)
    assert [u.port for u in spec.child_ports("offboard-3")] == [14542 + off]
    assert 7448 + off in {u.port for u in spec.child_ports("vehicle-sim")}


def test_the_cause_of_an_exit_is_the_last_error_line(tmp_path: Path) -> None:
    log = tmp_path / "offboard-1.log"
    log.write_text("INFO starting\nTraceback (most recent call last):\n  File \"x.py\", line 1\n"
                   "OSError: [Errno 98] Address already in use\nINFO bye\n")
    assert cause_line(log, 1) == "OSError: [Errno 98] Address already in use"
    log.write_text("INFO armed\nINFO offboard\n")
    assert cause_line(log, -9) == "killed by SIGKILL; last log line: INFO offboard"
    log.write_text("")
    assert cause_line(log, 3) == "exit code 3; its log is empty"


def test_a_bind_failure_names_the_port() -> None:
    mine = [PortUse("UDP", 14580, "vehicle 1 simulator API port"),
            PortUse("UDP", 14540, "agent 1 API port")]
    line = bind_failure_line(
        "offboard-1", "offboard: cannot open MAVLink udpin:127.0.0.1:14540: [Errno 98] "
        "Address already in use", Path("x.log"), mine)
    assert line is not None and line.startswith("udp 14540 (127.0.0.1, agent 1 API port) is")
    assert "offboard-1 could not bind it" in line and "x.log" in line
    assert bind_failure_line("offboard-1", "ValueError: bad gains", Path("x.log"), mine) is None


def test_a_daemon_dead_before_the_start_gives_its_cause(tmp_path: Path,
                                                       held_ports: HeldPorts) -> None:
    """A real child that exits as the daemon does on a busy port: the run's error is one
    line naming the port (a LaunchError, exit 2); on any other cause a MissionError that
    carries the last error line of its log."""
    off = _free_block(BASE, [1], 1)
    assert held_ports.udp(14540 + off)
    group = ProcessGroup(tmp_path)

    def die(name: str, text: str) -> None:
        group.start(name, [sys.executable, "-c", f"import sys; print({text!r}); sys.exit(1)"])
        group.children[-1].proc.wait(30)

    def ports_of(name: str) -> list[PortUse]:
        return [u for u in swarm_port_uses([1], off) if u.role == "agent 1 API port"]

    try:
        die("offboard-1", "OSError: [Errno 98] Address already in use")
        err = early_death(group, [1], ports_of)
        assert isinstance(err, LaunchError)
        assert str(err).startswith(f"udp {14540 + off} (127.0.0.1, agent 1 API port) is in use")
        assert "\n" not in str(err)
        group.stop()
        group.children.clear()
        die("offboard-2", "offboard: --signing-key: not a key file")
        err = early_death(group, [2], ports_of)
        assert isinstance(err, MissionError) and "\n" not in str(err)
        assert "agent(s) 2 exited before the start: offboard: --signing-key: not a key" in str(err)
    finally:
        group.stop()


def test_process_group_children_are_real(tmp_path: Path) -> None:
    """cause() reads what the child wrote (flushed log), not a stale buffer."""
    group = ProcessGroup(tmp_path)
    try:
        c = group.start("vehicle-sim", [sys.executable, "-c", "print('RuntimeError: boom')"])
        c.proc.wait(30)
        assert group.cause(c) == "RuntimeError: boom"
    finally:
        group.stop()
