"""The ``gcs dashboard`` hooks and their error paths (no Textual event loop needed)."""

from __future__ import annotations

import argparse
import socket

from cli_inproc import run_cli
from conftest import CUBE8  # noqa: E402

from gcs.dashboard.cli import add_dashboard_parser, run_dashboard

SCENARIO = CUBE8


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="gcs")
    sub = ap.add_subparsers(dest="command", required=True)
    add_dashboard_parser(sub)
    return ap


def test_hook_registers_subcommand():
    args = parser().parse_args(["dashboard", "--port-offset", "7", "--zenoh-connect", "tcp/x:1"])
    assert args.func is run_dashboard
    assert args.port_offset == 7 and args.zenoh_connect == ["tcp/x:1"]
    assert args.launch is None and not args.demo


def test_bad_scenario_is_one_line_exit_2(tmp_path):
    """Refused as the flags are parsed (swarm_common.inputs.bounded_file)."""
    r = run_cli("gcs", ["dashboard", "--scenario", str(tmp_path / "nope.toml")])
    err = r.stderr.strip()
    assert r.returncode == 2
    assert err.startswith("gcs dashboard:") and "nope.toml" in err and "\n" not in err


def test_busy_gcs_port_names_it(capsys, port_offset):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 14550 + port_offset))
    try:
        args = parser().parse_args(["dashboard", "--port-offset", str(port_offset), "--no-zenoh"])
        assert run_dashboard(args) == 2
        assert str(14550 + port_offset) in capsys.readouterr().err
        args = parser().parse_args(
            ["dashboard", "--launch", SCENARIO, "--port-offset", str(port_offset)]
        )
        assert run_dashboard(args) == 2
        assert f"udp {14550 + port_offset}" in capsys.readouterr().err
    finally:
        s.close()
