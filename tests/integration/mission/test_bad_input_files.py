"""Every file option of every command given what must never be read (issue 42): a device
streaming zeros, a FIFO with no writer, a 1 GiB sparse file and a directory. Each is one
line on stderr and exit status 2, at once and without reading. One fresh process per command
runs its ``main`` on the four for every file option of that command (the start-up imports
are paid once per command, not once per call), each call timed; the process's own peak RSS
is its VmHWM (/proc/self/status): a process, since a blocking read must be killable and a
read's memory measurable. Also the output paths that cannot be written: exit 2 before the
run starts (those refusals run ``main`` in this process, :func:`cli_inproc.run_cli`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_inproc import CliResult, run_cli
from conftest import CUBE8

pytestmark = pytest.mark.integration

KINDS = ("dev_zero", "fifo", "sparse", "directory")
TIMEOUT_S = 20.0  # robust under load; the assertions are far below it
# one process runs up to 32 refusals after its imports (11 s seen under load)
DRIVER_TIMEOUT_S = 45.0
MAX_ELAPSED_S = 2.0  # per refusal, the bound (measured: under 0.01 s)
# a whole process (interpreter start and imports included) that refuses its input: the
# guarantee is that it ends instead of waiting for ever; its start-up time depends on the
# machine's load (11 s seen beside a second copy of the suite), so the bound is generous
PROCESS_MAX_S = 50.0  # below the subprocess timeout (60 s)
# peak RSS of the whole process, interpreter included: the commands refuse a file as they
# parse their flags, before numpy, numba, Zenoh or pymavlink load (about 20-40 MB
# measured); reading the 1 GiB file or /dev/zero for even a second would be far above it
MAX_RSS_MB = 100.0
PY = sys.executable
SIM, OFFBOARD, GCS = "vehicle_sim.cli", "offboard.cli", "gcs.cli"

# (name, module, argv with {} for the file) for each file option of each command
OPTIONS = [
    ("sim-scenario", SIM, ["--scenario", "{}", "--no-zenoh"]),
    ("sim-params-file", SIM, ["--scenario", CUBE8, "--no-zenoh", "--params-file", "{}"]),
    ("sim-signing-key", SIM, ["--scenario", CUBE8, "--no-zenoh", "--signing-key", "{}"]),
    ("sim-zenoh-config", SIM, ["--scenario", CUBE8, "--zenoh-config", "{}"]),
    ("offboard-scenario", OFFBOARD, ["--scenario", "{}", "--agent", "1"]),
    ("offboard-signing-key", OFFBOARD, ["--scenario", CUBE8, "--agent", "1",
                                        "--signing-key", "{}"]),
    ("offboard-zenoh-config", OFFBOARD, ["--scenario", CUBE8, "--agent", "1",
                                         "--zenoh-config", "{}"]),
    ("gcs-run-scenario", GCS, ["mission", "run", "{}", "--inproc"]),
    ("gcs-run-signing-key", GCS, ["mission", "run", CUBE8, "--signing-key", "{}"]),
    ("gcs-compare-scenario", GCS, ["mission", "compare", "{}"]),
    ("gcs-sweep-scenario", GCS, ["mission", "sweep", "{}"]),
    ("gcs-router-scenario", GCS, ["router", "--scenario", "{}", "--secure-dir", "SECURE"]),
    ("gcs-dashboard-scenario", GCS, ["dashboard", "--scenario", "{}"]),
    ("gcs-dashboard-signing-key", GCS, ["dashboard", "--signing-key", "{}"]),
    ("gcs-dashboard-zenoh-config", GCS, ["dashboard", "--zenoh-config", "{}"]),
    ("gcs-dashboard-launch", GCS, ["dashboard", "--launch", "{}"]),
    ("gcs-export-scenario", GCS, ["log", "export", "RUN", "--format", "csv", "--out", "OUT",
                                  "--scenario", "{}"]),
]

# runs MODULE.main(argv) for each argv of argv[2] (JSON), stderr of each call captured
# alone; prints {"rc", "s", "err"} as one JSON line as each call ends (a call that blocks
# is the one after the last line)
DRIVER = """
import contextlib, importlib, io, json, sys, tempfile, time
main = importlib.import_module(sys.argv[1]).main
for argv in json.loads(sys.argv[2]):
    with tempfile.TemporaryFile("w+") as buf:  # a real file: faulthandler needs its fd
        t0 = time.monotonic()
        with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc = main(argv)
            except SystemExit as exc:
                rc = exc.code
        elapsed = time.monotonic() - t0
        buf.seek(0)
        print(json.dumps({"rc": rc, "s": elapsed, "err": buf.read()}), flush=True)
# this process's own peak (VmHWM: per address space, so it starts afresh at exec; the
# rusage of a forked child would also count its parent's pages before the exec)
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")]
print(int(hwm[0].split()[1]) / 1024.0 if hwm else 0.0)
"""


def _special(tmp_path: Path, kind: str) -> Path:
    if kind == "dev_zero":
        return Path("/dev/zero")
    p = tmp_path / kind
    if kind == "fifo":
        os.mkfifo(p, 0o600)
    elif kind == "sparse":
        with open(p, "wb") as f:
            f.truncate(1 << 30)
        os.chmod(p, 0o600)  # as a key file must be: refused for its size, not its mode
    else:
        p.mkdir(mode=0o700)
    return p


def _wait(proc: subprocess.Popen[bytes], t0: float,
          timeout_s: float = TIMEOUT_S) -> tuple[int, float]:
    """(exit code, peak RSS in MB) of ``proc``, reaped with ``wait4`` so the rusage is this
    child's alone; killed after ``timeout_s`` (a FIFO that blocked)."""
    while True:
        pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return proc.returncode, ru.ru_maxrss / 1024.0
        if time.monotonic() - t0 > timeout_s:
            proc.kill()
        time.sleep(0.02)


@pytest.mark.parametrize("module", [SIM, OFFBOARD, GCS])
def test_file_options_refuse_what_they_must_not_read(tmp_path, module):
    """Every file option of ``module``'s command given each of :data:`KINDS`."""
    paths = [_special(tmp_path, kind) for kind in KINDS]
    run = tmp_path / "run"  # never read: the bad --scenario is refused as flags are parsed
    named = {"SECURE": tmp_path / "secure", "RUN": run, "OUT": tmp_path / "out"}
    calls = [(name, kind, path,
              [str(path) if a == "{}" else str(named[a]) if a in named else a
               for a in argv])
             for name, mod, argv in OPTIONS if mod == module
             for kind, path in zip(KINDS, paths, strict=True)]
    with open(tmp_path / "out", "w+") as out:
        t0 = time.monotonic()
        proc = subprocess.Popen([PY, "-c", DRIVER, module, json.dumps([c[3] for c in calls])],
                                cwd=tmp_path, stdin=subprocess.DEVNULL, stdout=out,
                                stderr=subprocess.STDOUT)
        rc, rss_mb = _wait(proc, t0, DRIVER_TIMEOUT_S)
        out.seek(0)
        text = out.read()
    done = [json.loads(ln) for ln in text.splitlines() if ln.startswith("{")]
    # killed (a blocking read: the first call without its line) or crashed
    assert rc == 0, (calls[len(done)][:2] if len(done) < len(calls) else None, text)
    hwm_line = text.strip().splitlines()[-1]
    assert float(hwm_line) < MAX_RSS_MB, (hwm_line, rss_mb)
    for (name, kind, path, _), res in zip(calls, done, strict=True):
        lines = [ln for ln in res["err"].splitlines() if ln.strip()]
        assert res["rc"] == 2, (name, kind, res)
        assert len(lines) == 1 and "Traceback" not in res["err"], (name, kind, res["err"])
        assert str(path) in lines[0], (name, kind, lines[0])
        assert res["s"] < MAX_ELAPSED_S, (name, kind, res["s"])


def test_one_refusal_as_a_real_process(tmp_path):
    """The same refusal through the command's entry point: exit status 2, one line."""
    fifo = _special(tmp_path, "fifo")
    r, elapsed = _run([PY, "-m", SIM, "--scenario", CUBE8, "--no-zenoh", "--params-file",
                       str(fifo)], tmp_path)
    _one_line_exit_2(r, str(fifo), "not a regular file")
    assert elapsed < PROCESS_MAX_S


def _run(argv: list[str], cwd: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    t0 = time.monotonic()
    r = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT_S * 3)
    return r, time.monotonic() - t0


def _one_line_exit_2(r: subprocess.CompletedProcess[str] | CliResult, *expect: str) -> None:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for e in expect:
        assert e in lines[0], (e, lines[0])


def _run_inproc(prog: str, argv: list[str]) -> tuple[CliResult, float]:
    t0 = time.monotonic()
    r = run_cli(prog, argv)
    return r, time.monotonic() - t0


def test_unwritable_out_is_refused_before_the_run():
    """``--out /proc/nope/run``: exit 2 before anything runs (a 60 s in-process run would
    take far longer than the bound; nothing is written)."""
    r, elapsed = _run_inproc("gcs", ["mission", "run", CUBE8, "--inproc", "--out",
                                     "/proc/nope/run"])
    _one_line_exit_2(r, "--out /proc/nope/run")
    assert elapsed < PROCESS_MAX_S and r.stdout == ""


def test_vehicle_sim_unwritable_stats_out_exits_2(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    r, elapsed = _run_inproc("vehicle-sim", ["--scenario", CUBE8, "--no-zenoh", "--duration",
                                             "0.05", "--stats-out", str(blocker / "stats.json")])
    _one_line_exit_2(r, "--stats-out")
    assert elapsed < PROCESS_MAX_S


def test_offboard_port_offset_out_of_range_exits_2():
    """Once it waited forever for a router on port 107446."""
    for bad in ("99999", "-1"):
        r, elapsed = _run_inproc("offboard", ["--scenario", CUBE8, "--agent", "1",
                                              "--port-offset", bad])
        _one_line_exit_2(r, "--port-offset")
        assert elapsed < PROCESS_MAX_S
