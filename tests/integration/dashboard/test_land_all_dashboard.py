"""Dashboard ``l`` (docs/lifecycle.md): all vehicles with Zenoh up -> one Zenoh land-all
command at the swarm's mission time + LAND_LEAD_S; otherwise AUTO.LAND per vehicle."""

from __future__ import annotations

import pytest
from conftest import free_tcp_port, settle, wait_for  # noqa: E402
from dashboard_fakes import FakeCommander

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.commands import LiveCommander
from gcs.dashboard.group_commands import COMMAND_REPEATS, LAND_LEAD_S
from gcs.dashboard.view.recorded import recorded_source
from gcs.dashboard.zenoh_feed import ZenohFeed
from offboard.daemon.zenoh.link import SwarmBus
from swarm_common.wire import Command
from swarm_common.zenoh_session import open_session


@pytest.mark.asyncio
async def test_land_all_goes_out_as_one_zenoh_command() -> None:
    cmd = FakeCommander(up=True, t=12.5)
    app = DashboardApp(recorded_source(), cmd)
    app.command_repeat_s = 0.01  # the copies' spacing, short for the test
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "l", "y")
        assert await settle(app, pilot, lambda: len(cmd.zenoh_calls) >= 2)
        assert cmd.mav_calls == []
        c = cmd.zenoh_calls[0]
        assert c.kind == "land" and c.agent == 0
        assert c.at_s == pytest.approx(12.5 + LAND_LEAD_S)
        # the same command again (COMMAND_REPEATS): a put lost to one daemon is not final
        assert len(cmd.zenoh_calls) == 1 + COMMAND_REPEATS
        assert all(copy == c for copy in cmd.zenoh_calls)


@pytest.mark.asyncio
async def test_single_vehicle_or_no_zenoh_uses_auto_land() -> None:
    cmd = FakeCommander(up=True, t=12.5)
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("down", "down", "l")  # vehicle 3 only
        assert await settle(app, pilot, lambda: bool(cmd.mav_calls))
        assert cmd.mav_calls == [(3, "land")] and cmd.zenoh_calls == []
    down = FakeCommander(up=False, t=12.5)
    app = DashboardApp(recorded_source(), down)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "l", "y")
        assert await settle(app, pilot, lambda: len(down.mav_calls) > 1)
        assert {k for _, k in down.mav_calls} == {"land"} and down.zenoh_calls == []


def test_feed_land_command_reaches_the_agents_bus() -> None:
    """ZenohFeed (dashboard) -> offboard.daemon.zenoh.link.SwarmBus (daemon): the land command with
    its at_s, and the feed's mission time from the agents' status."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    agent_session = open_session(listen=[ep])
    bus = SwarmBus(agent_session, "t2", 3)
    feed = ZenohFeed("t2", ids=[3], connect=[ep]).start()
    got: list[Command] = []
    try:
        commander = LiveCommander(feed=feed)
        assert commander.zenoh_up() and commander.mission_time() is None

        def send() -> bool:
            commander.zenoh(Command(kind="land", at_s=7.25))
            bus.pump()
            got.extend(bus.pop_commands())
            return bool(got)

        assert wait_for(send)
        assert got[0].kind == "land" and got[0].at_s == 7.25
    finally:
        feed.close()
        bus.close()
        agent_session.close()




