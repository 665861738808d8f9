"""Typed input of the three commands (issue 42): bad flags are one line and exit 2 at
parse time, numbers too large for a float are one-line scenario errors, results that cannot
be written go to a fallback folder, and a component without a key says it is unsigned."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import CUBE8

from gcs.cli import build_parser as gcs_parser
from gcs.mission.run_output import empty_series, write_run
from offboard.cli import build_parser as offboard_parser
from swarm_common.scenario.model import ScenarioError, load_scenario
from vehicle_sim.cli import build_parser as sim_parser

pytestmark = pytest.mark.unit

BIG = str(2**64)


def _refused(parser, argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as ei:
        parser.parse_args(argv)
    assert ei.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    return lines[0]


SIM = ["--scenario", CUBE8]


@pytest.mark.parametrize(
    ("argv", "flag"),
    [(["--port-offset", "99999"], "--port-offset"), (["--port-offset", "-1"], "--port-offset"),
     (["--seed", BIG], "--seed"), (["--seed", "-1"], "--seed"),
     (["--remote-host", "999.1.1.1"], "--remote-host"), (["--bind", "a b"], "--bind"),
     (["--zenoh-connect", "localhost"], "--zenoh-connect"),
     (["--zenoh-listen", "tcp/127.0.0.1:70000"], "--zenoh-listen"),
     (["--vehicles", "0"], "--vehicles"), (["--duration", "nan"], "--duration"),
     (["--odometry-hz", "1e400"], "--odometry-hz"),
     (["--offboard-timeout", "-1"], "--offboard-timeout")],
)
def test_vehicle_sim_bad_flags(argv, flag, capsys):
    line = _refused(sim_parser(), SIM + argv, capsys)
    assert line.startswith("vehicle-sim: error:") and flag in line


@pytest.mark.parametrize(
    ("argv", "flag"),
    [(["--port-offset", "99999"], "--port-offset"), (["--port-offset", "-1"], "--port-offset"),
     (["--seed", BIG], "--seed"), (["--zenoh-connect", "tcp/bad!host:7447"], "--zenoh-connect"),
     (["--zenoh-listen", "7447"], "--zenoh-listen"), (["--agent", "256"], "--agent")],
)
def test_offboard_bad_flags(argv, flag, capsys):
    base = ["--scenario", CUBE8] + ([] if "--agent" in argv else ["--agent", "1"])
    line = _refused(offboard_parser(), base + argv, capsys)
    assert line.startswith("offboard: error:") and flag in line


@pytest.mark.parametrize(
    ("argv", "flag"),
    [(["mission", "run", CUBE8, "--seed", BIG], "--seed"),
     (["mission", "run", CUBE8, "--port-offset", "99999"], "--port-offset"),
     (["mission", "run", CUBE8, "--kill-agent", "0"], "--kill-agent"),
     (["mission", "run", CUBE8, "--land-at", "inf"], "--land-at"),
     (["mission", "compare", CUBE8, "--seed", BIG], "--seed"),
     (["router", "--listen", "tcp/127.0.0.1"], "--listen"),
     (["dashboard", "--zenoh-connect", "nope"], "--zenoh-connect"),
     (["dashboard", "--port-offset", "-1"], "--port-offset"),
     (["dashboard", "--ack-timeout", "0"], "--ack-timeout"),
     (["dashboard", "--retries", "1e9"], "--retries"),
     (["dashboard", "--log-dir", "/proc/nope/logs"], "--log-dir")],
)
def test_gcs_bad_flags(argv, flag, capsys):
    line = _refused(gcs_parser(), argv, capsys)
    assert line.startswith("gcs ") and flag in line


def test_the_three_commands_share_one_port_offset_bound(capsys):
    from swarm_common.inputs import MAX_PORT_OFFSET

    top = str(MAX_PORT_OFFSET)
    assert sim_parser().parse_args(SIM + ["--port-offset", top]).port_offset == MAX_PORT_OFFSET
    assert offboard_parser().parse_args(
        ["--scenario", CUBE8, "--agent", "1", "--port-offset", top]).port_offset == int(top)
    assert gcs_parser().parse_args(
        ["mission", "run", CUBE8, "--port-offset", top]).port_offset == int(top)
    over = str(MAX_PORT_OFFSET + 1)
    for parser, argv in ((sim_parser(), SIM), (offboard_parser(), ["--scenario", CUBE8,
                                                                   "--agent", "1"]),
                         (gcs_parser(), ["mission", "run", CUBE8])):
        assert "--port-offset" in _refused(parser, [*argv, "--port-offset", over], capsys)


@pytest.mark.parametrize("digits", [400, 5000])
def test_integer_too_large_for_a_float_is_a_one_line_scenario_error(tmp_path, digits):
    text = Path(CUBE8).read_text()
    assert "duration_s = 60.0" in text
    p = tmp_path / "big.toml"
    p.write_text(text.replace("duration_s = 60.0", "duration_s = 1" + "0" * digits, 1))
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert "\n" not in msg and len(msg) < 300 and str(p) in msg


def test_write_run_falls_back_to_a_temp_folder(tmp_path, caplog):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    ser = empty_series(np.arange(3) * 0.1, 2)
    doc = {"scenario": "s", "metrics": {"rms": 1.5}}
    with caplog.at_level(logging.ERROR):
        where = write_run(blocker / "run", doc, ser)  # a file in the way: mkdir fails
    assert where != blocker / "run" and where.is_dir()
    assert json.loads((where / "metrics.json").read_text()) == doc
    with np.load(where / "series.npz") as z:
        np.testing.assert_array_equal(z["t"], ser.t)
    assert any(str(where) in r.getMessage() for r in caplog.records)
    ok = write_run(tmp_path / "ok", doc, ser)  # a writable folder: no fallback
    assert ok == tmp_path / "ok" and (ok / "metrics.json").is_file()


def test_stats_fall_back_to_a_temp_folder(tmp_path, caplog):
    from vehicle_sim.stats import write_json_or_fallback

    blocker = tmp_path / "file"
    blocker.write_text("x")
    with caplog.at_level(logging.ERROR):
        where = write_json_or_fallback({"steps": 3}, str(blocker / "stats.json"))
    assert where != str(blocker / "stats.json")
    assert json.loads(Path(where).read_text()) == {"steps": 3}
    assert any(where in r.getMessage() for r in caplog.records)


@pytest.mark.full
def test_vehicle_sim_without_a_key_warns_once(capfd):
    """One WARNING line as a simulator without a key starts (a subprocess: the run installs
    signal handlers), none when it is refused."""
    from vehicle_sim.cli import UNSIGNED_WARNING

    argv = [sys.executable, "-m", "vehicle_sim.cli", *SIM, "--no-zenoh", "--duration", "0.05",
            "--log-level", "warning"]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stderr.count(UNSIGNED_WARNING) == 1, r.stderr
    r = subprocess.run([*argv, "--vehicles", "99"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and UNSIGNED_WARNING not in r.stderr, r.stderr
    assert r.stderr.count("\n") == 1


def test_offboard_without_a_key_warns_once(monkeypatch, capfd):
    import offboard.cli as cli

    def no_router(*_a, **_k):
        raise ValueError("no router in this test")

    monkeypatch.setattr(cli, "open_session_saying", no_router)
    root = logging.getLogger()  # main() configures the logging tree: put it back after
    monkeypatch.setattr(root, "handlers", list(root.handlers))
    monkeypatch.setattr(root, "level", root.level)
    assert cli.main(["--scenario", CUBE8, "--agent", "1", "--log-level", "warning"]) == 2
    err = capfd.readouterr().err
    assert err.count("accepts unsigned MAVLink") == 1
    assert err.strip().splitlines()[-1].startswith("offboard: cannot open Zenoh session")
