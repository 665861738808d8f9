"""Dashboard ``u`` (docs/lifecycle.md): OFFBOARD + arm every vehicle, then one Zenoh take-off
command; a real-time ``--manual-start`` ground start holds on its pads until then.

The live test drives the real app headless against ``gcs dashboard --launch
scenarios/ground8.toml`` (simulator in real time, eight daemons): ``t`` ``u``, the layered
climb, ``l``, everyone back on the ground with no collision."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import signal
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest
from conftest import ROOT, free_port_offset, settle
from dashboard_fakes import FakeCommander

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.cli import build, configure_parser
from gcs.dashboard.group_commands import COMMAND_REPEATS, TAKEOFF_LEAD_S
from gcs.dashboard.view.recorded import recorded_source
from gcs.dashboard.widgets import EventLog
from offboard.agent.takeoff import takeoff_plan
from swarm_common.scenario.model import load_scenario
from swarm_common.wire import Command, Truth, WireError, decode, key_truth

GROUND8 = ROOT / "scenarios" / "ground8.toml"
EARLY_S = 2.5  # s after t0: the plan's climbs are at 1 m/s·(2.5 − 0.5) s = 2 m
STALL_S = 3.0  # s a stalled daemon's process stays stopped (its vehicle's failsafe: 0.5 s)
STALLED = 1  # the agent whose daemon is stalled


def log_text(app: DashboardApp) -> str:
    return "\n".join(app.query_one(EventLog).lines_text)


@pytest.mark.asyncio
async def test_takeoff_key_offboard_arm_then_one_zenoh_command() -> None:
    """One take-off command, published again (the same at_s) a few times: a Zenoh put is
    lost to a daemon whose link is congested or reconnecting (gcs.dashboard.app)."""
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    app.command_repeat_s = 0.01  # the copies' spacing, short for the test
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "u", "y")
        assert await settle(app, pilot, lambda: len(cmd.zenoh_calls) >= 2)
        ids = app.all_ids()
        assert len(ids) > 1
        # every vehicle to OFFBOARD first, then every vehicle armed, then the take-off
        assert cmd.mav_calls == [(i, "offboard") for i in ids] + [(i, "arm") for i in ids]
        c = cmd.zenoh_calls[0]
        assert c.kind == "takeoff" and c.agent == 0
        assert c.at_s == pytest.approx(4.0 + TAKEOFF_LEAD_S)
        assert len(cmd.zenoh_calls) == 1 + COMMAND_REPEATS
        assert all(copy == c for copy in cmd.zenoh_calls)
        assert log_text(app).count("take-off at t=5.00 s (all) published") == 1


@pytest.mark.asyncio
async def test_takeoff_key_refused_or_not_all() -> None:
    cmd = FakeCommander(refuse=3)  # vehicle 3 refuses to arm: no take-off command
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "u", "y")
        assert await settle(app, pilot, lambda: "take-off not sent" in log_text(app))
        assert "arm refused by #3" in log_text(app) and cmd.zenoh_calls == []
    for commander, keys in ((FakeCommander(), ("u",)), (FakeCommander(up=False), ("t", "u"))):
        one = DashboardApp(recorded_source(), commander)
        async with one.run_test(size=(80, 24)) as pilot:
            await pilot.press(*keys)  # one vehicle, or all without Zenoh: refused, nothing sent
            assert await settle(one, pilot, lambda a=one: "take-off is for all" in log_text(a))
            assert commander.mav_calls == [] and commander.zenoh_calls == []


async def until(pilot, pred, timeout: float, each=lambda: None) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        await pilot.pause(0.1)
        each()
        if pred():
            return True
    return False


def _daemon_takeoffs(launch) -> dict[str, tuple[bool, list[float], bool]]:
    """Per daemon log: (held on its pad at start, take-off times it logged, whether the
    command reached it late: offboard.daemon.commands, it then climbs from its step time)."""
    out = {}
    for c in launch.group.children[1:]:
        text = c.log_path.read_text(errors="replace")
        t0 = [float(x) for x in re.findall(r"take-off at t=([0-9.]+) s", text)]
        out[c.name] = ("on its pad until the take-off command" in text, t0, "arrived late" in text)
    return out


def _daemon_lines(launch) -> str:
    """The daemons' take-off lines and warnings (a failure's context)."""
    keep = ("take-off", "WARNING", "ERROR")
    return "\n".join(
        f"{c.name}: {line}" for c in launch.group.children[1:]
        for line in c.log_path.read_text(errors="replace").splitlines()
        if any(k in line for k in keep)
    )


def _record_truth(feed, leaders: set[int], leader_z: dict[float, float]) -> None:
    """Record (mission time, the leaders' highest altitude) of every truth ``feed`` takes
    in, on the feed's own reader thread (it runs no Python on the router's threads:
    gcs.dashboard.zenoh_feed)."""
    ingest, key = feed.ingest, key_truth(feed.swarm)

    def record(k: str, data: bytes) -> None:
        ingest(k, data)
        if k != key:
            return
        try:
            m = decode(data)
        except WireError:
            return
        if isinstance(m, Truth):
            leader_z[float(m.t)] = max(
                float(m.p[j][2]) for j, i in enumerate(m.ids) if i in leaders)

    feed.ingest = record


def _stall_on_commands(app: DashboardApp, launch, agent: int) -> Callable[[], None]:
    """Stop (SIGSTOP) agent ``agent``'s daemon process as the dashboard publishes the
    take-off or the land-all command, and resume it (SIGCONT) STALL_S later from a timer
    thread: a stalled companion computer, the command reaching that daemon only after it
    resumes, late (offboard.daemon.commands). The stall is STALL_S whatever the test's own
    loop does meanwhile: resumed from that loop, a loaded machine once kept the daemon
    stopped past its vehicle-lost timeout (5 s), and it exited. The returned function
    resumes it at once (a daemon that has exited has nothing to resume)."""
    (child,) = [c for c in launch.group.children if c.name == f"offboard-{agent}"]
    publish = app.send_zenoh

    def resume() -> None:
        with contextlib.suppress(ProcessLookupError):
            os.kill(child.proc.pid, signal.SIGCONT)

    def send(cmd: Command) -> None:
        if cmd.kind in ("takeoff", "land"):
            os.kill(child.proc.pid, signal.SIGSTOP)
            threading.Timer(STALL_S, resume).start()
        publish(cmd)

    app.send_zenoh = send  # type: ignore[method-assign]
    return resume


@pytest.mark.asyncio
@pytest.mark.slow
async def test_dashboard_takeoff_and_land_ground8(tmp_path) -> None:
    """Daemon 1's process is stopped for STALL_S from the take-off command on, and again
    from the land-all (offboard.daemon.commands: it then climbs, and lands on its pad,
    timed from its own step). The seven others take the commands on time, so one run checks
    both paths: the plan started at t0 by every daemon that was not stalled, the late start
    of the stalled one, and the layered climb and the landing of all."""
    sc = load_scenario(GROUND8)
    plan = takeoff_plan(sc)
    args = configure_parser(argparse.ArgumentParser()).parse_args(
        ["--launch", str(GROUND8), "--port-offset", str(free_port_offset()),
         "--log-dir", str(tmp_path)]
    )  # fmt: skip
    app, source, launch, _ = build(args)
    ids = list(sc.ids)
    z_max = dict.fromkeys(ids, 0.0)
    leaders = set(sc.formation.leaders)
    # (mission time, the leaders' highest altitude (m)) of every truth message the feed
    # takes in, recorded on its reader thread; the altitude up to t0 + EARLY_S is read
    # after the run, once t0 is known: a loaded machine can stall the test's loop for
    # seconds between the take-off and the line that logs its t0
    leader_z: dict[float, float] = {}
    _record_truth(source.feed, leaders, leader_z)
    truth_z_max = dict.fromkeys(ids, 0.0)
    t0 = np.inf
    min_dist = np.inf
    resume = _stall_on_commands(app, launch, STALLED)

    def sample() -> None:
        nonlocal min_dist
        v = app.view
        if v is None or v.sim_time is None:
            return
        if v.min_dist is not None:
            min_dist = min(min_dist, v.min_dist)
        for r in v.rows:
            if r.pos is not None:
                z_max[r.id] = max(z_max[r.id], r.pos[2])
        truth = source.feed.snapshot().truth if source.feed is not None else None
        if truth is not None:
            for k, i in enumerate(truth.ids):
                truth_z_max[i] = max(truth_z_max[i], float(truth.p[k][2]))

    def rows_z() -> list[float]:
        assert app.view is not None
        return [r.pos[2] if r.pos is not None else np.nan for r in app.view.rows]

    async def watch(pred, timeout: float) -> bool:
        return await until(pilot, pred, timeout, sample)

    try:
        app.poll_s = 0.1
        async with app.run_test(size=(120, 40)) as pilot:
            ready = lambda: (  # noqa: E731
                app.view is not None and app.view.sim_time is not None
                and all(r.pos is not None and not r.status_missing for r in app.view.rows)
            )
            assert await watch(ready, timeout=60.0), launch.dead()
            await pilot.press("t", "u", "y")  # y: the group command's confirmation
            # OFFBOARD, then arm, ACKed by every vehicle first: that took more than 20 s
            # (with retries) with three CPU burners and a callgrind run beside the test
            assert await watch(lambda: "take-off at t=" in log_text(app), 60.0), (
                log_text(app)[-1500:])
            t0 = float(re.findall(r"take-off at t=([0-9.]+) s", log_text(app))[0])
            await pilot.pause(STALL_S)  # the stalled daemon resumes meanwhile, by its timer

            def airborne() -> bool:
                return all(z > 1.5 for z in z_max.values())

            assert await watch(airborne, timeout=30.0), (
                f"shown {z_max}, truth {truth_z_max}, dead {launch.dead()}\n"
                + _daemon_lines(launch)
            )
            # formed: leaders on their trajectory (after t_traj of the shifted plan)
            t_traj = takeoff_plan(sc, t0).t_traj
            assert await watch(lambda: app.view.sim_time >= t_traj, timeout=30.0)
            await pilot.press("l", "y")
            assert await watch(lambda: "land-all at t=" in log_text(app), 10.0)
            await pilot.pause(STALL_S)  # resumed by its timer meanwhile

            def down() -> bool:
                return max(rows_z()) < 0.1

            assert await watch(down, timeout=40.0), (rows_z(), launch.dead())
            collisions = app.view.collisions
    finally:
        resume()
        source.close()
        launch.stop()
    held = _daemon_takeoffs(launch)
    early_leader_z = max((z for t, z in leader_z.items() if t <= t0 + EARLY_S), default=0.0)
    n_window = sum(t0 <= t <= t0 + EARLY_S for t in leader_z)
    print(f"t0 = {t0:.2f} s, min distance {min_dist:.3f} m, early leader z {early_leader_z:.2f}"
          f" m ({n_window} truth messages recorded in [t0, t0 + {EARLY_S} s]), z_max {z_max}")
    assert collisions == 0
    assert all(z > 1.5 for z in z_max.values()), z_max
    # every daemon held its agent and started the one plan at t0 (or, reached late after a
    # stall of its loop, from its own step time; offboard.daemon.commands) ...
    assert all(h and len(t) == 1 and (late or t[0] == pytest.approx(t0))
               for h, t, late in held.values()), held
    # ... and the leaders climbed with the plan of t0 (2 m at t0 + 2.5 s), not from when
    # armed (t0 - TAKEOFF_LEAD_S: 3 m by then)
    assert early_leader_z < 3.0, (early_leader_z, _daemon_lines(launch))
    # the top layer climbed higher than the bottom layer (layered staging altitudes)
    top = [i for k, i in enumerate(ids) if plan.z_stage[k] > plan.z_stage.min() + 1.0]
    assert min(z_max[i] for i in top) > 0.8 * plan.z_stage.max()
