"""Issue "PX4 client surface", acceptance: in a real distributed run every daemon is a
MAVLink component a GCS can see (its own HEARTBEAT, MAV_TYPE_ONBOARD_CONTROLLER, as
component 191 of its vehicle's system) and numbers its frames (pymavlink's ``mavloss``
counts no loss for it in the daemon's ``.tlog``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from conftest import CUBE8, ROOT, free_port_offset  # noqa: E402
from pymavlink import mavutil  # noqa: E402

pytestmark = pytest.mark.timeout(240)
M = mavutil.mavlink
ONBOARD = M.MAV_COMP_ID_ONBOARD_COMPUTER


def test_every_daemon_sends_heartbeats_with_contiguous_sequence(tmp_path: Path) -> None:
    out = tmp_path / "run"
    r = subprocess.run(
        [sys.executable, "-m", "gcs.cli", "mission", "run", CUBE8, "--duration", "3",
         "--port-offset", str(free_port_offset()), "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=200,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    for vid in range(1, 9):
        log = mavutil.mavlink_connection(str(out / f"vehicle_{vid}.tlog"))
        beats = 0
        seqs: list[int] = []
        while (m := log.recv_match()) is not None:
            if (m.get_srcSystem(), m.get_srcComponent()) != (vid, ONBOARD):
                continue
            seqs.append(m.get_seq())
            if m.get_type() == "HEARTBEAT":
                beats += 1
                assert m.type == M.MAV_TYPE_ONBOARD_CONTROLLER
                assert m.autopilot == M.MAV_AUTOPILOT_INVALID
        assert beats >= 1, f"vehicle {vid}: no daemon HEARTBEAT"
        assert len(seqs) > 100
        gaps = sum((b - a) % 256 != 1 for a, b in zip(seqs, seqs[1:], strict=False))
        assert gaps == 0, f"vehicle {vid}: {gaps} sequence gaps from component 191"
