"""The fork server's own start and end (gcs.launch.preload): it dies at once when the
runner that started it is gone before it watches the runner's pipe, and it skips the
interpreter's teardown at its exit. Each case runs ``import gcs.launch.preload`` in an
interpreter of its own, as the server does."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from conftest import ROOT

from gcs.launch.forkserver import PARENT_ENV


def _import_preload(parent: str, code: str = "import gcs.launch.preload") -> \
        subprocess.CompletedProcess[str]:
    env = {**os.environ, PARENT_ENV: parent}
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


def test_a_server_whose_runner_is_already_gone_kills_itself() -> None:
    # the named runner is not this interpreter's parent: it died and we were re-parented
    not_parent = os.getppid()  # pytest's parent, never the child's parent
    done = _import_preload(str(not_parent), "import gcs.launch.preload\nprint('lived')")
    assert done.returncode == -signal.SIGKILL, (done.returncode, done.stderr[-500:])
    assert "lived" not in done.stdout


def test_a_server_whose_runner_lives_imports_and_skips_the_teardown() -> None:
    # an exit hook registered before the preload's would run in the teardown; the
    # preload's hook runs first and ends the process
    code = ("import atexit\n"
            "atexit.register(lambda: print('teardown', flush=True))\n"
            "import gcs.launch.preload\n"
            "print('imported', flush=True)\n")
    done = _import_preload(str(os.getpid()), code)
    assert done.returncode == 0, done.stderr[-500:]
    assert done.stdout.split() == ["imported"]


def test_a_malformed_parent_variable_falls_back_to_the_parent() -> None:
    for text in ("-1", "99999999999999"):
        done = _import_preload(text, "import gcs.launch.preload\nprint('ok', flush=True)")
        assert (done.returncode, done.stdout.split()) == (0, ["ok"]), (text, done.stderr[-300:])


# a parent that forks a child asking for SIGKILL at the parent's death (and, with
# "take-back", taking that back), waits for the child's "ready", and exits; the child
# says "outlived" once it sees it has a new parent
_ORPHAN = (
    "import os, signal, sys, time\n"
    "from swarm_common.process_life import die_with_parent, outlive_parent\n"
    "r, w = os.pipe()\n"
    "parent = os.getpid()\n"
    "if os.fork() == 0:\n"
    "    die_with_parent(signal.SIGKILL, parent)()\n"
    "    if sys.argv[1] == 'take-back':\n"
    "        outlive_parent()\n"
    "    os.write(1, b'ready\\n')\n"
    "    os.write(w, b'x')\n"
    "    end = time.monotonic() + 60.0\n"
    "    while os.getppid() == parent and time.monotonic() < end:\n"
    "        time.sleep(0.01)\n"
    "    os.write(1, b'outlived\\n')\n"
    "    os._exit(0)\n"
    "os.read(r, 1)\n"
    "os._exit(0)\n"
)


def test_outlive_parent_takes_back_the_death_signal() -> None:
    out = {}
    for mode in ("keep", "take-back"):
        # stdout's pipe stays open until the child ends too
        done = subprocess.run([sys.executable, "-c", _ORPHAN, mode], cwd=ROOT,
                              capture_output=True, text=True, timeout=120)
        out[mode] = done.stdout.split()
    assert out["keep"] == ["ready"]
    assert out["take-back"] == ["ready", "outlived"]
