"""Variants of cube8 with one bad key, shared by the unit and CLI tests."""

from __future__ import annotations

from pathlib import Path

from conftest import CUBE8


def scenario_variant(tmp_path: Path, old: str, new: str) -> Path:
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
    ('method = "dcbf"', 'method = "magic"', ["controller.method", "'rcbf'", "'apf'"]),
    ("zeta_spread = 0.2", "zeta_spread = -0.2", ["unmodeled.zeta_spread", "[0, 1]"]),
    ("position = [4.0, 0.0, 6.0]", "position = [4.0, 0.0]", ["agent[0].position", "3 numbers"]),
    ("[sensing]", "[sensingg]\nx = 1\n[sensing]", ["sensingg", "allowed"]),
    # unsafe before it starts: agent 3 starts 0.2 m from agent 4; a vertex 0.4 m from another
    ("position = [2.0, 0.4, 2.9]", "position = [2.0, 0.4, 4.9]", ["agent[3].position", "d_safe_m"]),
    ("vertex = [0, 0, 1]", "vertex = [0, 0, 0.1]", ["agent[3].vertex", "d_safe_m"]),
    # infeasible leader trajectory (needs more acceleration than the input set allows)
    ("frequency_hz = 0.2", "frequency_hz = 0.4",
     ["leader_trajectory.frequency_hz = 0.4", "--allow-infeasible"]),
]
