"""Scenario files: cube8 loads; bad keys, types and ranges give one line naming the key."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT, load_shipped
from scenario_variants import CASES, scenario_variant

from swarm_common.scenario.model import ScenarioError, load_scenario


def test_cube8_loads():
    sc = load_scenario(CUBE8)
    assert sc.name == "cube8" and sc.n == 8
    assert sc.ids == list(range(1, 9))
    assert sc.leader_ids == [1, 2]
    assert sc.substeps_per_control == 4
    assert sc.control_dt == pytest.approx(0.02)
    assert sc.vehicle.mass_kg == pytest.approx(1.8)
    assert sc.initial_positions()[0].tolist() == [4.0, 0.0, 6.0]
    assert sc.outages == ((5.0, 5.5), (15.0, 15.5), (40.0, 40.5))


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios").glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_scenario_loads(path):
    """Valid and feasible (swarm_common.scenario.feasibility): no --allow-infeasible needed."""
    sc = load_shipped(path)
    assert sc.n >= 2 and not sc.allow_infeasible


@pytest.mark.parametrize(("old", "new", "expect"), CASES)
def test_invalid_values_name_the_key(tmp_path, old, new, expect):
    p = scenario_variant(tmp_path, old, new)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert "\n" not in msg
    assert str(p) in msg
    for e in expect:
        assert e in msg, (e, msg)


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "nope.toml")
    p = tmp_path / "x.toml"
    p.write_text("[scenario\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(p)


def _cube8_with(tmp_path, old: str, new: str, name: str = "v.toml"):
    text = (ROOT / "scenarios" / "cube8.toml").read_text()
    assert old in text
    p = tmp_path / name
    p.write_text(text.replace(old, new, 1))
    return p


def _one_line_error(path) -> str:
    with pytest.raises(ScenarioError) as ei:
        load_scenario(path)
    msg = str(ei.value)
    assert "\n" not in msg and str(path) in msg
    return msg


@pytest.mark.parametrize("bad", ["", "**", "x$*y", "../../x", "a/b", "a?b", "a//b", "a b",
                                 "-lead", "é", "x" * 65])
def test_bad_swarm_names_are_refused(tmp_path, bad):
    """The name becomes Zenoh keys and a run directory: no wildcard, separator or ``..``."""
    p = _cube8_with(tmp_path, 'name = "cube8"', f"name = {bad!r}".replace("'", '"'))
    assert "scenario.name" in _one_line_error(p)


def test_good_swarm_name_loads(tmp_path):
    p = _cube8_with(tmp_path, 'name = "cube8"', 'name = "Blue_2-x"')
    assert load_scenario(p).name == "Blue_2-x"


def test_non_utf8_file(tmp_path):
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe[scenario]\n")
    assert "not UTF-8" in _one_line_error(p)


def test_deeply_nested_arrays(tmp_path):
    p = tmp_path / "deep.toml"
    p.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    assert "nested deeper" in _one_line_error(p)


def test_brackets_inside_strings_do_not_count(tmp_path):
    p = _cube8_with(tmp_path, 'name = "cube8"', 'name = "cube8"  # ' + "[" * 100)
    assert load_scenario(p).name == "cube8"


def test_device_fifo_and_directory_are_refused(tmp_path):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    for p in (Path("/dev/zero"), fifo, tmp_path):
        assert "not a regular file" in _one_line_error(p)


def test_oversized_file(tmp_path):
    p = tmp_path / "big.toml"
    p.write_text("# " + "x" * (2 << 20) + "\n")
    assert "larger than" in _one_line_error(p)


def test_duplicate_leaders_and_leaders_only(tmp_path):
    p = _cube8_with(tmp_path, "leaders = [1, 2]", "leaders = [1, 1]")
    assert "duplicate agent id" in _one_line_error(p)
    text = (ROOT / "scenarios" / "cube8.toml").read_text()
    text = text.replace("leaders = [1, 2]", f"leaders = {list(range(1, 9))}", 1)
    p = tmp_path / "lonly.toml"
    p.write_text(text.replace('role = "follower"', 'role = "leader"'))
    assert "need a follower" in _one_line_error(p)
