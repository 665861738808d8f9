"""swarm_common.faults: FaultConfig / FaultPlan validation and the seeded FaultInjector
(with a fake clock and a fake send function; no thread, no socket)."""

from __future__ import annotations

import time
import tomllib
from pathlib import Path

import pytest

from swarm_common import faults
from swarm_common.faults import FaultConfig, FaultError, FaultInjector, FaultPlan
from swarm_common.scenario.model import ScenarioError, dump_toml, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parents[3]
CUBE8 = ROOT / "scenarios" / "cube8.toml"


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def make(cfg: FaultConfig, seed: int = 1) -> tuple[FaultInjector, FakeClock, list[int]]:
    clock = FakeClock()
    return FaultInjector(cfg, seed, 3, "mavlink", clock=clock, threaded=False), clock, []


def test_all_zero_sends_everything_at_once_in_order() -> None:
    inj, _, got = make(FaultConfig())
    for k in range(100):
        inj.send(k, got.append)
    assert got == list(range(100)) and inj.pending == 0


def test_drop_rate_and_reproducible_draws() -> None:
    inj, _, got = make(FaultConfig(drop=0.2))
    for k in range(5000):
        inj.send(k, got.append)
    assert 0.17 < 1 - len(got) / 5000 < 0.23
    assert inj.stats.dropped == 5000 - len(got)
    again, _, got2 = make(FaultConfig(drop=0.2))
    for k in range(5000):
        again.send(k, got2.append)
    assert got2 == got  # same seed, agent and link: the same messages are lost
    other, _, got3 = make(FaultConfig(drop=0.2), seed=2)
    for k in range(5000):
        other.send(k, got3.append)
    assert got3 != got


def test_delay_holds_until_due_without_blocking() -> None:
    inj, clock, got = make(FaultConfig(delay_ms=20.0))
    inj.send("a", got.append)
    assert got == [] and inj.pending == 1
    clock.t += 0.019
    inj.service()
    assert got == []
    clock.t += 0.002
    inj.service()
    assert got == ["a"]


def test_jitter_stays_within_its_spread() -> None:
    inj, clock, got = make(FaultConfig(delay_ms=20.0, jitter_ms=5.0))
    for k in range(200):
        inj.send(k, got.append)
    clock.t += 0.0149
    inj.service()
    assert got == []
    clock.t += 0.0102
    inj.service()
    assert sorted(got) == list(range(200))


def test_duplicate_sends_twice() -> None:
    inj, _, got = make(FaultConfig(duplicate=1.0))
    inj.send("x", got.append)
    assert got == ["x", "x"] and inj.stats.duplicated == 1


def test_reorder_swaps_with_the_next_message() -> None:
    inj, clock, got = make(FaultConfig(reorder=0.5))
    for k in range(400):
        inj.send(k, got.append)
        clock.t += 0.001
        inj.service()
    clock.t += 1.0
    inj.service()
    assert sorted(got) == list(range(400))  # nothing lost, nothing added
    swaps = sum(1 for a, b in zip(got, got[1:], strict=False) if b < a)
    # every hold is a swap, except a hold of the last message (released in order)
    assert inj.stats.reordered - 1 <= swaps <= inj.stats.reordered
    assert swaps > 50


def test_held_message_is_released_when_no_next_comes() -> None:
    inj, clock, got = make(FaultConfig(reorder=1.0))
    inj.send("only", got.append)
    assert got == []
    clock.t += faults.REORDER_MAX_HOLD_S + 0.001
    inj.service()
    assert got == ["only"]


def test_drop_inbound() -> None:
    inj, _, _ = make(FaultConfig(drop_in=0.5))
    n = sum(inj.drop_inbound() for _ in range(2000))
    assert 900 < n < 1100 and inj.stats.dropped_in == n
    assert not make(FaultConfig(drop=1.0))[0].drop_inbound()


def test_threaded_timer_sends_delayed_messages() -> None:
    got: list[int] = []
    inj = FaultInjector(FaultConfig(delay_ms=1.0), 1, 1, "zenoh")
    try:
        for k in range(10):
            inj.send(k, got.append)
        deadline = time.monotonic() + 10.0
        while len(got) < 10 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sorted(got) == list(range(10))
    finally:
        inj.close()


# -- the [faults] scenario section --------------------------------------------------------
def cube8_with(faults_table: dict) -> dict:
    data = tomllib.loads(CUBE8.read_text())
    data["faults"] = faults_table
    return data


def test_plan_links_and_per_agent_override() -> None:
    sc = parse_scenario(cube8_with({
        "mavlink": {"drop": 0.2}, "zenoh": {"drop": 0.1, "delay_ms": 20},
        "agent": {"3": {"mavlink": {"drop": 0.5}}},
    }))  # fmt: skip
    assert sc.faults.for_agent(1, "mavlink") == FaultConfig(drop=0.2)
    assert sc.faults.for_agent(3, "mavlink") == FaultConfig(drop=0.5)
    assert sc.faults.for_agent(3, "zenoh") == FaultConfig(drop=0.1, delay_ms=20.0)
    # round trip through TOML text (the run directory's scenario.toml)
    again = parse_scenario(tomllib.loads(dump_toml(sc.to_toml_dict())))
    assert again.faults == sc.faults


def test_no_faults_section_means_no_injector(tmp_path: Path) -> None:
    sc = load_scenario(CUBE8)
    assert not sc.faults.active and "faults" not in sc.to_toml_dict()
    assert faults.injector_for("mavlink", 1) is None
    p = tmp_path / "f.toml"
    p.write_text(dump_toml(cube8_with({"zenoh": {"drop": 0.2}})))
    load_scenario(p)
    try:
        assert faults.injector_for("mavlink", 1) is None
        inj = faults.injector_for("zenoh", 1)
        assert inj is not None and inj.cfg.drop == 0.2
    finally:
        load_scenario(CUBE8)
    assert faults.injector_for("zenoh", 1) is None


@pytest.mark.parametrize(
    ("table", "expect"),
    [
        ({"mavlink": {"drop": 1.5}}, "faults.mavlink.drop = 1.5: must be a number in [0, 1]"),
        ({"mavlink": {"drop": True}}, "faults.mavlink.drop = True: must be"),
        ({"zenoh": {"delay_ms": -1}}, "faults.zenoh.delay_ms = -1: must be a number in"),
        ({"zenoh": {"lag": 1}}, "unknown key faults.zenoh.lag; allowed: drop, drop_in"),
        ({"udp": {"drop": 0.1}}, "unknown key faults.udp; allowed: mavlink, zenoh, agent"),
        ({"mavlink": 0.2}, "[faults.mavlink] must be a table"),
        ({"agent": {"x": {}}}, "faults.agent.x: must be an agent id"),
        ({"agent": {"99": {"mavlink": {"drop": 0.1}}}}, "faults.agent.99: 99 is not an"),
        ({"agent": {"2": {"radio": {}}}}, "unknown key faults.agent.2.radio"),
    ],
)
def test_bad_faults_table_is_one_line(table: dict, expect: str) -> None:
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(cube8_with(table), "x.toml")
    assert expect in str(exc.value) and "\n" not in str(exc.value)


def test_flags_override_links_and_agents() -> None:
    plan = FaultPlan.parse({"mavlink": {"delay_ms": 5}, "agent": {"2": {"mavlink": {}}}})
    out = plan.with_link_values(("mavlink",), {"drop": 0.3})
    assert out.for_agent(1, "mavlink") == FaultConfig(drop=0.3, delay_ms=5.0)
    assert out.for_agent(2, "mavlink").drop == 0.3
    assert not out.for_agent(1, "zenoh").active
    with pytest.raises(FaultError):
        faults.check_fault_value("--fault-drop", "drop", 2.0)
