"""``gcs mission run --fault-*`` (docs/faults.md): a bad value or combination is one line and
exit 2; good flags write the run's scenario with its ``[faults]`` into the run directory.
Every case ends before a run starts: ``gcs``'s ``main`` runs in this process
(:func:`cli_inproc.run_cli`)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from cli_inproc import CliResult, run_cli
from conftest import CUBE8

from swarm_common.scenario.model import load_scenario


def gcs(*argv: str) -> CliResult:
    return run_cli("gcs", list(argv))


@pytest.mark.parametrize(
    ("flags", "expect"),
    [
        (["--fault-drop", "1.5"], "--fault-drop: '1.5': must be a number in [0, 1]"),
        (["--fault-drop", "nan"], "--fault-drop: 'nan': must be a number in [0, 1]"),
        (["--fault-drop", "x"], "--fault-drop: 'x' is not a number"),
        (["--fault-delay-ms", "-3"], "--fault-delay-ms: '-3': must be a number in [0, 10000]"),
        (["--fault-reorder", "2"], "--fault-reorder: '2': must be a number in [0, 1]"),
        (["--fault-link", "radio", "--fault-drop", "0.1"], "--fault-link: invalid choice"),
        (["--fault-link", "zenoh"], "--fault-link needs a --fault-* value"),
        (["--inproc", "--fault-drop", "0.1"], "--fault-* flags need a distributed run"),
    ],
)
def test_bad_fault_flags_one_line_exit_2(flags: list[str], expect: str) -> None:
    r = gcs("mission", "run", CUBE8, "--duration", "1", *flags)
    assert r.returncode == 2
    assert expect in r.stderr.strip().splitlines()[-1]
    assert "Traceback" not in r.stderr


def test_bad_faults_section_in_the_scenario_one_line_exit_2(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(Path(CUBE8).read_text() + "\n[faults.mavlink]\ndrop = 1.2\n")
    r = gcs("mission", "run", str(p), "--duration", "1")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "faults.mavlink.drop = 1.2: must be a number in [0, 1]" in lines[0]


def test_flags_write_the_run_scenario(tmp_path: Path) -> None:
    """The written scenario (what every process of the run loads) carries the flags on the
    chosen link only, over the scenario's own [faults]. The run itself never starts:
    ``--kill-agent`` of an unknown id exits 2 after the scenario is written."""
    base = tmp_path / "base.toml"
    base.write_text(Path(CUBE8).read_text() + "\n[faults.zenoh]\ndelay_ms = 5\n")
    out = tmp_path / "run"
    r = gcs("mission", "run", str(base), "--duration", "1", "--out", str(out),
            "--fault-drop", "0.25", "--fault-jitter-ms", "3", "--fault-link", "zenoh",
            "--kill-agent", "99")
    assert r.returncode == 2 and "--kill-agent 99" in r.stderr
    doc = tomllib.loads((out / "scenario.toml").read_text())
    assert doc["faults"] == {"zenoh": {"drop": 0.25, "delay_ms": 5.0, "jitter_ms": 3.0}}
    sc = load_scenario(out / "scenario.toml")
    assert sc.faults.for_agent(4, "zenoh").drop == 0.25
    assert not sc.faults.for_agent(4, "mavlink").active
    assert sc.to_toml_dict()["agent"] == load_scenario(CUBE8).to_toml_dict()["agent"]
