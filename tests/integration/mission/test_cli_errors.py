"""Command lines given a bad scenario or flag: non-zero exit and one stderr line.

The refusals run the command's ``main`` in this process (:func:`cli_inproc.run_cli`); what
could block (a FIFO, ``/dev/zero``) or runs a mission is a real process.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from cli_inproc import CliResult, run_cli
from conftest import CUBE8, ROOT
from scenario_variants import CASES, scenario_variant


@pytest.mark.parametrize(("old", "new", "expect"), CASES[:3])
def test_cli_exits_nonzero_with_one_line(tmp_path, old, new, expect):
    p = scenario_variant(tmp_path, old, new)
    r = run_cli("vehicle-sim", ["--scenario", str(p), "--no-zenoh"])
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    for e in expect:
        assert e in lines[0]


def test_cli_bad_vehicles_count(tmp_path):
    r = run_cli("vehicle-sim", ["--scenario", CUBE8, "--vehicles", "9"])
    assert r.returncode != 0
    assert r.stderr.strip().count("\n") == 0 and "--vehicles" in r.stderr


def _gcs_process(*args: str) -> subprocess.CompletedProcess[str]:
    """A real ``gcs`` process: for what runs or could block."""
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def _gcs(*args: str) -> CliResult:
    return run_cli("gcs", list(args))


def test_infeasible_scenario_exits_2_unless_allowed(tmp_path):
    """cube8's trajectory at 0.4 Hz needs more acceleration than the input set allows: one
    line naming the key and the flag, exit 2; with --allow-infeasible it runs (a warning)."""
    p = scenario_variant(tmp_path, "frequency_hz = 0.2", "frequency_hz = 0.4")
    r = _gcs("mission", "run", str(p), "--inproc", "--duration", "0.2")
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "leader_trajectory.frequency_hz = 0.4" in lines[0]
    assert "--allow-infeasible" in lines[0]
    r2 = _gcs_process("mission", "run", str(p), "--inproc", "--duration", "0.2", "--json",
                      "--allow-infeasible")  # it runs: a real process
    assert r2.returncode == 0, r2.stderr
    assert "WARNING" in r2.stderr and "leader_trajectory.frequency_hz = 0.4" in r2.stderr
    assert r2.stdout.strip().startswith("{")


def _one_line_exit_2(r: subprocess.CompletedProcess[str] | CliResult, *expect: str) -> None:
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in r.stderr
    assert lines, r.stderr
    for e in expect:
        assert e in lines[-1], (e, lines[-1])
    # argparse prints its usage first; everything else is exactly one line
    if not lines[0].startswith("usage:"):
        assert len(lines) == 1, r.stderr


def _variant(tmp_path, old: str, new: str):
    text = (ROOT / "scenarios" / "cube8.toml").read_text()
    assert old in text
    p = tmp_path / "v.toml"
    p.write_text(text.replace(old, new, 1))
    return str(p)


def test_bad_scenario_files_exit_2(tmp_path):
    import os

    nonutf = tmp_path / "bin.toml"
    nonutf.write_bytes(b"\xff\xfe[scenario]\n")
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    cases = [
        (str(nonutf), "not UTF-8"),
        (str(deep), "nested deeper"),
        (_variant(tmp_path, "leaders = [1, 2]", "leaders = [1, 1]"), "duplicate agent id"),
    ]
    for path, expect in cases:
        _one_line_exit_2(_gcs("mission", "run", path, "--inproc", "--duration", "0.1"), expect)
    # a read of either would never end: a process the timeout can stop
    for path in ("/dev/zero", str(fifo)):
        _one_line_exit_2(_gcs_process("mission", "run", path, "--inproc", "--duration", "0.1"),
                         "not a regular file")


@pytest.mark.parametrize("name", ["", "**", "x$*y", "../../x", "a?b", "a//b"])
def test_bad_swarm_names_exit_2(tmp_path, name):
    p = _variant(tmp_path, 'name = "cube8"', f'name = "{name}"')
    _one_line_exit_2(_gcs("mission", "run", p, "--inproc", "--duration", "0.1"),
                     "scenario.name")


@pytest.mark.parametrize(
    ("argv", "expect"),
    [
        (["--duration", "0.001"], "shorter than one control step"),
        (["--duration", "1e308"], "--duration"),
        (["--port-offset", "-1"], "--port-offset"),
        (["--port-offset", "70000"], "--port-offset"),
        (["--seed", "-1"], "--seed"),
    ],
)
def test_bad_run_flags_exit_2(argv, expect):
    _one_line_exit_2(_gcs("mission", "run", CUBE8, *argv), expect)


def test_out_that_is_a_file_exits_2(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    _one_line_exit_2(_gcs("mission", "run", CUBE8, "--inproc", "--duration", "0.1",
                          "--out", str(f)), "not a directory")


def test_compare_jobs_0_exits_2():
    _one_line_exit_2(_gcs("mission", "compare", CUBE8, "--inproc", "--jobs", "0"), "--jobs")


def test_router_needs_scenario_and_dir_together(tmp_path):
    _one_line_exit_2(_gcs("router", "--listen", "tcp/127.0.0.1:1", "--secure-dir",
                          str(tmp_path)), "go together")


@pytest.mark.parametrize(
    "argv",
    [
        ["vehicle-sim", "--scenario", CUBE8, "--no-zenoh", "--swarm", "a?b"],
        ["offboard", "--scenario", CUBE8, "--agent", "1", "--swarm", "a?b"],
        ["vehicle-sim", "--scenario", CUBE8, "--no-zenoh", "--zenoh-config", "/nonexistent"],
        ["offboard", "--scenario", CUBE8, "--agent", "1", "--zenoh-config", "/nonexistent"],
        ["offboard", "--scenario", CUBE8, "--agent", "3", "--nav-gate", "nan"],
    ],
)
def test_sim_and_daemon_bad_swarm_or_zenoh_config_exit_2(argv):
    _one_line_exit_2(run_cli(argv[0], argv[1:]), argv[-2])


@pytest.mark.parametrize(
    ("argv", "expect"),
    [
        (["--no-signing", "--signing-key", "KEY"], "--no-signing"),
        (["--no-signing", "--unsigned-gcs-link"], "--unsigned-gcs-link"),
        (["--signing-key", "/nonexistent/key"], "key file"),
    ],
)
def test_bad_signing_flags_exit_2(tmp_path, argv, expect):
    """KEY: a valid key file (a missing or bad one is refused as the flags are parsed)."""
    key = tmp_path / "swarm.key"
    key.write_text("ab" * 32 + "\n")
    key.chmod(0o600)
    argv = [str(key) if a == "KEY" else a for a in argv]
    _one_line_exit_2(_gcs("mission", "run", CUBE8, "--duration", "0.1", *argv), expect)


def test_world_readable_signing_key_exits_2(tmp_path):
    key = tmp_path / "swarm.key"
    key.write_text("ab" * 32 + "\n")
    key.chmod(0o644)
    _one_line_exit_2(_gcs("mission", "run", CUBE8, "--duration", "0.1", "--signing-key",
                          str(key)), "chmod 600")
