"""The dashboard against a real ``vehicle-sim`` subprocess over loopback UDP.

Random free port offset; every wait bounded; no timing assertions on speed.
"""

from __future__ import annotations

import argparse
import stat
import time

import pytest
from conftest import ROOT, start_child, stop_processes  # noqa: E402

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.cli import build, configure_parser
from gcs.dashboard.commands import LiveCommander
from gcs.dashboard.mavlink_gcs import MavlinkGcs
from gcs.dashboard.view.state import LiveSource
from gcs.dashboard.widgets import EventLog
from gcs.mission.procs import python_entry
from swarm_common.scenario.model import load_scenario

SCENARIO = ROOT / "scenarios" / "cube8.toml"

pytestmark = pytest.mark.skipif(
    not (ROOT / "vehicle_sim" / "cli.py").exists(), reason="vehicle-sim not in the tree"
)


@pytest.fixture
def sim(port_offset, tmp_path):
    proc = start_child(
        [*python_entry("vehicle_sim.cli"), "--scenario", str(SCENARIO),
         "--port-offset", str(port_offset), "--no-zenoh", "--duration", "60", "--quiet"],
        tmp_path / "sim.log",
    )  # fmt: skip
    yield port_offset
    stop_processes([proc], grace_s=5.0)


def log_text(app) -> str:
    return "\n".join(app.query_one(EventLog).lines_text)


async def until(app, pilot, pred, timeout=15.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        await app.workers.wait_for_complete()
        await pilot.pause(0.05)
        if pred():
            return True
    return pred()


@pytest.mark.asyncio
@pytest.mark.slow
async def test_dashboard_commands_real_sim(sim):
    sc = load_scenario(SCENARIO)
    link = MavlinkGcs(port_offset=sim).start()
    source = LiveSource(sc, link, None)
    app = DashboardApp(source, LiveCommander(link, None, timeout_s=1.0), poll_s=0.1)
    try:
        async with app.run_test(size=(100, 30)) as pilot:
            # every vehicle shows up with a position and a live link
            assert await until(
                app, pilot,
                lambda: app.view is not None
                and all(r.pos is not None and not r.link_lost for r in app.view.rows),
            )  # fmt: skip
            r4 = app.view.row(4)
            assert r4.pos == pytest.approx((2.0, 0.4, 5.1), abs=0.5)
            assert r4.mode == "POSCTL" and r4.armed is False
            assert app.view.min_dist is not None and app.view.min_dist_history
            await pilot.press("down", "down", "down")  # vehicle 4
            await pilot.press("a")
            assert await until(app, pilot, lambda: "#4 arm: ACCEPTED" in log_text(app))
            assert await until(app, pilot, lambda: app.view.row(4).armed)
            # no offboard daemon streams setpoints: OFFBOARD must be refused, and say so
            await pilot.press("f")
            assert await until(
                app, pilot, lambda: "#4 start formation (OFFBOARD):" in log_text(app)
            )
            assert "#4 start formation (OFFBOARD): ACCEPTED" not in log_text(app)
            await pilot.press("h")
            assert await until(
                app, pilot, lambda: "#4 hold (AUTO.LOITER): ACCEPTED" in log_text(app)
            )
            assert await until(app, pilot, lambda: app.view.row(4).mode == "AUTO.LOITER")
            await pilot.press("l")
            assert await until(app, pilot, lambda: "#4 land: ACCEPTED" in log_text(app))
            await pilot.press("t", "d", "y")  # disarm all (y: the group confirmation)
            assert await until(app, pilot, lambda: log_text(app).count("disarm:") == 8)
            await pilot.press("t", "x", "y")  # emergency stop of #4 only
            assert await until(app, pilot, lambda: "#4 emergency stop:" in log_text(app))
            assert link.bad_packets == 0
    finally:
        source.close()


@pytest.mark.asyncio
async def test_launch_sim_with_zenoh(port_offset, tmp_path):
    args = configure_parser(argparse.ArgumentParser()).parse_args(
        ["--launch", str(SCENARIO), "--port-offset", str(port_offset), "--no-daemons",
         "--log-dir", str(tmp_path)]
    )  # fmt: skip
    app, source, launch, _ = build(args)
    try:
        app.poll_s = 0.1
        async with app.run_test(size=(80, 24)) as pilot:
            assert await until(
                app, pilot,
                lambda: app.view is not None and app.view.sim_time is not None
                and all(r.pos is not None and not r.link_lost for r in app.view.rows),
                timeout=30.0,
            )  # fmt: skip
            # no daemons: every agent's status is missing, and shown so
            assert all(r.status_missing and r.failsafe == "NO-OFB" for r in app.view.rows)
            assert app.view.zenoh.startswith("missing")
            await pilot.press("t", "o", "enter")  # outage on all: published
            assert await until(app, pilot, lambda: "outage 0.5 s (all) published" in log_text(app))
            sim = launch.group.children[0]
            assert sim.proc.poll() is None
            # security defaults: a fresh 0600 key in a private 0700 directory; the GCS link
            # signs and verifies, and every vehicle frame it received passed the check
            secure = launch.secure_dir
            assert secure is not None and stat.S_IMODE(secure.stat().st_mode) == 0o700
            assert stat.S_IMODE((secure / "mavlink.key").stat().st_mode) == 0o600
            assert app.view.signed and source.link.signed and source.link.rejected == 0
    finally:
        source.close()
        launch.stop()
    assert launch.group.children[0].proc.poll() is not None  # stopped on exit
    assert not secure.exists()  # the key and the credentials died with the launch
