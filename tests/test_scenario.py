"""Scenario files: cube8 loads; bad keys, types and ranges give one line naming the key."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import CUBE8, ROOT

from swarm_common.scenario import ScenarioError, load_scenario


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


def _variant(tmp_path: Path, old: str, new: str) -> Path:
    text = Path(CUBE8).read_text()
    assert old in text, old
    p = tmp_path / "bad.toml"
    p.write_text(text.replace(old, new, 1))
    return p


CASES = [
    # (old text, new text, substrings the one-line error must contain)
    ("mass_kg = 1.8", "mass_kg = 1.8\nmass_lb = 4.0", ["vehicle.mass_lb", "allowed", "mass_kg"]),
    ("control_hz = 50", 'control_hz = "fifty"', ["scenario.control_hz", "integer"]),
    ("tilt_max_deg = 30.0", "tilt_max_deg = 95.0", ["vehicle.tilt_max_deg", "(0, 89]"]),
    ('method = "rcbf"', 'method = "magic"', ["controller.method", "'rcbf'", "'apf'"]),
    ("zeta_spread = 0.2", "zeta_spread = -0.2", ["unmodeled.zeta_spread", "[0, 1]"]),
    ("position = [4.0, 0.0, 6.0]", "position = [4.0, 0.0]", ["agent[0].position", "3 numbers"]),
    ("[sensing]", "[sensingg]\nx = 1\n[sensing]", ["sensingg", "allowed"]),
]


@pytest.mark.parametrize(("old", "new", "expect"), CASES)
def test_invalid_values_name_the_key(tmp_path, old, new, expect):
    p = _variant(tmp_path, old, new)
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


@pytest.mark.parametrize(("old", "new", "expect"), CASES[:3])
def test_cli_exits_nonzero_with_one_line(tmp_path, old, new, expect):
    p = _variant(tmp_path, old, new)
    r = subprocess.run(
        [sys.executable, "-m", "vehicle_sim.cli", "--scenario", str(p), "--no-zenoh"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    for e in expect:
        assert e in lines[0]


def test_cli_bad_vehicles_count(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "vehicle_sim.cli", "--scenario", CUBE8, "--vehicles", "9"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode != 0
    assert r.stderr.strip().count("\n") == 0 and "--vehicles" in r.stderr
