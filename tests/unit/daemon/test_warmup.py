"""The daemon's kernel warm-up (offboard.daemon.warmup): it steps throwaway agents and leaves
nothing behind, and a failure in it is a warning, never a daemon that does not start."""

from __future__ import annotations

import logging
from pathlib import Path

import numba
import numpy as np
import pytest

import offboard.daemon.warmup as warmup
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario

SC = load_scenario(Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml")
# un-jitted (NUMBA_DISABLE_JIT=1) the kernels are plain functions: nothing to load
needs_jit = pytest.mark.skipif(bool(numba.config.DISABLE_JIT),
                               reason="NUMBA_DISABLE_JIT: no compiled kernels to load")


def test_warm_up_steps_throwaway_agents_and_mutes_their_logs(
    caplog: pytest.LogCaptureFixture,
) -> None:
    form = formation_from_scenario(SC)
    with caplog.at_level(logging.INFO):
        cpu = warmup.warm_kernels(SC, "dcbf", form)
    assert cpu >= 0.0
    assert not [r for r in caplog.records if r.levelno >= logging.INFO]
    assert logging.root.manager.disable == logging.NOTSET  # logging restored


def test_a_failing_warm_up_is_a_warning(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture,
) -> None:
    def broken(*_: object, **__: object) -> None:
        raise np.linalg.LinAlgError("singular")

    monkeypatch.setattr(warmup, "make_agent", broken)
    with caplog.at_level(logging.WARNING):
        warmup.warm_kernels(SC, "dcbf", formation_from_scenario(SC))
    assert any("kernel warm-up skipped (LinAlgError: singular)" in r.getMessage()
               for r in caplog.records)
    assert logging.root.manager.disable == logging.NOTSET


@pytest.mark.full
@needs_jit
def test_simulator_warm_up_loads_the_period_physics_kernel() -> None:
    """vehicle_sim.server.load_kernels loads the kernel each lockstep step runs
    (``steps_kernel``, through ``SwarmDynamics.advance_period``), checked in a fresh
    process, where nothing else has loaded it."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[3]
    code = (
        "from swarm_common.scenario.model import load_scenario\n"
        "from vehicle_sim.physics.dynamics_kernel import steps_kernel\n"
        "from vehicle_sim.server import load_kernels\n"
        "assert not steps_kernel.signatures\n"
        f"load_kernels(load_scenario({str(root / 'scenarios' / 'cube8.toml')!r}))\n"
        "print(len(steps_kernel.signatures))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                         text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.split()[-1]) >= 1


@pytest.mark.full
@needs_jit
def test_daemon_warm_up_loads_the_dcbf_step_and_qp_kernels() -> None:
    """warm_kernels steps the throwaway follower through its dcbf step in one compiled
    call (offboard.safety.dcbf.front; the kernels it calls, the nominal law and the rows
    among them, are compiled into it), so its kernels are loaded, the QP's past its
    shortcut among them (the throwaway follower's
    steps at rest reach it), and the neighbour prediction of an outage (its last period
    is silent); checked in a fresh process, where nothing else has loaded them."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[3]
    code = (
        "from swarm_common.scenario.model import load_scenario\n"
        "from offboard.estimation.bearing import formation_from_scenario\n"
        "from offboard.safety.dcbf.front import dcbf_front_into\n"
        "from offboard.safety.dcbf.exact_kernel import pre_solve_kernel\n"
        "from offboard.safety.qp_rows_kernel import write_rows_kernel\n"
        "from offboard.daemon.warmup import warm_kernels\n"
        "from offboard.estimation.predictor import predict_row_into\n"
        "ks = (dcbf_front_into, pre_solve_kernel, write_rows_kernel, predict_row_into)\n"
        "assert not any(k.signatures for k in ks)\n"
        f"sc = load_scenario({str(root / 'scenarios' / 'cube8.toml')!r})\n"
        "warm_kernels(sc, 'dcbf', formation_from_scenario(sc))\n"
        "print(*[len(k.signatures) for k in ks])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                         text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    assert all(int(c) >= 1 for c in out.stdout.split()[-4:])
