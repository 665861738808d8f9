"""The live view's flags (docs/records.md, "Live view"): ``--foxglove-host`` an IP address,
``--foxglove-port`` in 0..65535, neither without ``--foxglove``; bad input is one line and
exit 2 at parse time, for ``gcs mission run`` and ``gcs dashboard`` alike."""

from __future__ import annotations

import pytest
from conftest import CUBE8

from gcs.cli import build_parser
from gcs.records.live import DEFAULT_HOST, DEFAULT_PORT, live_endpoint, ws_url

pytestmark = pytest.mark.unit

RUN = ["mission", "run", CUBE8, "--foxglove"]
DASHBOARD = ["dashboard", "--foxglove"]


@pytest.mark.parametrize("cmd", [RUN, DASHBOARD], ids=["mission-run", "dashboard"])
@pytest.mark.parametrize(
    ("argv", "flag"),
    [(["--foxglove-host", "localhost"], "--foxglove-host"),
     (["--foxglove-host", "999.1.1.1"], "--foxglove-host"),
     (["--foxglove-host", ""], "--foxglove-host"),
     (["--foxglove-host", "127.0.0.1:8765"], "--foxglove-host"),
     (["--foxglove-port", "65536"], "--foxglove-port"),
     (["--foxglove-port", "-1"], "--foxglove-port"),
     (["--foxglove-port", "8765.0"], "--foxglove-port"),
     (["--foxglove-port", "ws"], "--foxglove-port")],
)
def test_bad_host_or_port_is_one_line_and_exit_2(cmd, argv, flag, capsys):
    with pytest.raises(SystemExit) as ei:
        build_parser().parse_args(cmd + argv)
    assert ei.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("gcs") and flag in lines[0]


def test_defaults_and_choices():
    args = build_parser().parse_args(RUN)
    assert live_endpoint(args) == (DEFAULT_HOST, DEFAULT_PORT) == ("127.0.0.1", 8765)
    args = build_parser().parse_args(RUN + ["--foxglove-host", "::1", "--foxglove-port", "0"])
    assert live_endpoint(args) == ("::1", 0)
    assert live_endpoint(build_parser().parse_args(["mission", "run", CUBE8])) is None
    assert ws_url("::1", 8765) == "ws://[::1]:8765"
    assert ws_url("0.0.0.0", 0) == "ws://0.0.0.0:0"


@pytest.mark.parametrize(("flag", "value"),
                         [("--foxglove-host", "127.0.0.1"), ("--foxglove-port", "9000")])
def test_a_live_flag_without_foxglove_is_refused(flag, value):
    args = build_parser().parse_args(["mission", "run", CUBE8, flag, value])
    with pytest.raises(ValueError, match=f"^{flag} needs --foxglove$"):
        live_endpoint(args)


@pytest.mark.parametrize("mode", [["--demo"], ["--replay", "runs/none"]], ids=["demo", "replay"])
def test_the_dashboard_refuses_foxglove_without_a_live_swarm(mode):
    from gcs.dashboard.cli import build

    args = build_parser().parse_args(DASHBOARD + mode)
    with pytest.raises(ValueError, match="^--foxglove serves a live swarm"):
        build(args)
