"""The real exit path of each command line, and :func:`cli_inproc.run_cli` putting the test
process back.

The refusal tests call the commands' ``main`` in the test process (``run_cli``); these are
the few that start the installed console scripts (``gcs``, ``vehicle-sim``, ``offboard``:
``sys.exit(main())``) and the runner's ``python -m offboard`` (``exit_now``, no teardown)
with one bad flag: exit status 2 and one line on stderr. ``python -m gcs.cli`` and ``-m
vehicle_sim.cli`` are real processes in ``test_cli_errors.py`` (a FIFO, ``/dev/zero``)
and ``test_bad_input_files.py``.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from cli_inproc import COMMAND_ENV, run_cli
from conftest import CUBE8, ROOT
from scenario_variants import scenario_variant

from swarm_common.zenoh_session import ZENOH_CONFIG_ENV

pytestmark = pytest.mark.timeout(120)
BIN = Path(sys.executable).parent


def _script(name: str, module: str) -> list[str]:
    """The installed console script, or ``python -m`` where it is not installed."""
    path = BIN / name
    return [str(path)] if path.exists() else [sys.executable, "-m", module]


@pytest.mark.parametrize(
    ("argv", "expect"),
    [
        ([*_script("gcs", "gcs.cli"), "mission", "run", CUBE8, "--seed", "-1"],
         "gcs mission run: error: argument --seed: '-1'"),
        ([*_script("vehicle-sim", "vehicle_sim.cli"), "--scenario", CUBE8, "--no-zenoh",
          "--vehicles", "9"], "vehicle-sim: --vehicles 9: must be in [1, 8]"),
        ([*_script("offboard", "offboard.cli"), "--scenario", CUBE8, "--agent", "1",
          "--mavlink", "udpin:127.0.0.1:0"], "offboard: --mavlink 'udpin:127.0.0.1:0': "),
        ([sys.executable, "-m", "offboard", "--scenario", CUBE8, "--agent", "1",
          "--nav-gate", "nan"], "offboard: --nav-gate 'nan'"),
    ],
    ids=["gcs", "vehicle-sim", "offboard", "python-m-offboard"],
)
def test_bad_flag_exits_2_with_one_line(argv: list[str], expect: str) -> None:
    r = subprocess.run(argv, cwd=ROOT, stdin=subprocess.DEVNULL, capture_output=True,
                       text=True, timeout=90)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(expect), r.stderr
    assert r.stdout == ""


def _state() -> dict[str, Any]:
    """What a command's ``main`` may change in the process (cli_inproc's docstring)."""
    handlers = {}
    for sig in signal.valid_signals():
        try:
            handlers[sig] = signal.getsignal(sig)
        except (ValueError, OSError):
            continue
    root = logging.getLogger()
    return {"root": (list(root.handlers), root.level), "disable": logging.root.manager.disable,
            "signals": handlers, "environ": dict(os.environ), "cwd": os.getcwd()}


def test_run_cli_captures_the_log_and_puts_the_process_back(tmp_path: Path) -> None:
    """Each command configures logging (a handler on the captured stderr) and ``gcs
    mission`` installs SIGINT/SIGTERM handlers before refusing: the log line is in the
    result, and afterwards the process is as it was. Each case runs once first: what its
    lazy imports leave for good in the environment (cli_inproc's docstring) is not the
    call's to undo."""
    infeasible = scenario_variant(tmp_path, "frequency_hz = 0.2", "frequency_hz = 0.4")
    cases = [
        ("gcs", ["mission", "run", str(infeasible), "--allow-infeasible", "--duration",
                 "0.001"], "shorter than one control step"),
        ("offboard", ["--scenario", CUBE8, "--agent", "1", "--swarm", "a?b"], "--swarm"),
        ("vehicle-sim", ["--scenario", CUBE8, "--no-zenoh", "--vehicles", "9"], "--vehicles 9"),
    ]
    first = _state()
    for prog, argv, _ in cases:
        run_cli(prog, argv)
    before = _state()
    assert {**before, "environ": None} == {**first, "environ": None}
    for prog, argv, expect in cases:
        r = run_cli(prog, argv)
        assert r.returncode == 2 and r.stdout == "", r
        lines = r.stderr.splitlines()
        assert lines[-1].startswith(prog) and expect in lines[-1], r.stderr
        if prog == "gcs":  # the loader's warning, through configure_logging's handler
            assert len(lines) == 2 and " WARNING " in lines[0], r.stderr
        else:
            assert len(lines) == 1, r.stderr
        assert _state() == before, prog
    assert ZENOH_CONFIG_ENV in COMMAND_ENV  # vehicle-sim --zenoh-config sets it
    with pytest.raises(ValueError, match="--die-with-parent"):
        run_cli("offboard", ["--scenario", CUBE8, "--agent", "1", "--die-with-par"])


@pytest.mark.parametrize("module", ["vehicle_sim.cli", "offboard.cli"])
def test_a_bad_zenoh_config_in_the_environment_is_one_line_exit_2(module: str) -> None:
    """``$SWARM_ZENOH_CONFIG`` is not a flag, so the parse cannot check it: the command checks
    it before anything starts (a process: a regression would open sockets or wait for a
    router)."""
    env = {**os.environ, ZENOH_CONFIG_ENV: "/dev/zero"}
    r = subprocess.run([sys.executable, "-m", module, "--scenario", str(CUBE8), "--agent", "1"]
                       if module == "offboard.cli" else
                       [sys.executable, "-m", module, "--scenario", str(CUBE8), "--duration",
                        "0.05"], env=env, capture_output=True, text=True, timeout=60)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, r.stderr[-2000:]
    assert lines and "$SWARM_ZENOH_CONFIG: /dev/zero" in lines[-1], r.stderr[-2000:]
    assert "Traceback" not in r.stderr
