"""Dashboard ``g`` and the mission panel (gcs.dashboard.view.mission_progress): a typed centroid
goes out as one checked Zenoh "mission" command; a bad entry is one ERROR line and sends
nothing; the panel and the top view show the mission's next waypoint and its path."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import settle
from dashboard_fakes import FakeCommander

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.view.recorded import recorded_source
from gcs.dashboard.widgets import EventLog, FormationView, InputScreen, MissionPanel
from gcs.formation.steer import FormationSteer
from swarm_common.scenario.model import load_scenario

pytestmark = pytest.mark.asyncio
ROOT = Path(__file__).resolve().parents[3]


def mission_app(cmd: FakeCommander) -> DashboardApp:
    steer = FormationSteer(load_scenario(ROOT / "scenarios" / "course8.toml"))
    return DashboardApp(recorded_source(), cmd, steer=steer)


def log_text(app: DashboardApp) -> str:
    return "\n".join(app.query_one(EventLog).lines_text)


async def type_goto(pilot, text: str) -> None:
    await pilot.press("g")
    await pilot.pause()
    assert isinstance(pilot.app.screen, InputScreen)
    await pilot.press(*["space" if ch == " " else ch for ch in text], "enter")
    await pilot.pause()


async def test_typed_goto_sends_a_mission_command_and_the_panel_follows_it():
    cmd = FakeCommander()  # Zenoh up, mission time 4 s: course8 rests at (2, 2, 4) till 10 s
    app = mission_app(cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        panel = app.query_one(MissionPanel)
        assert panel.display and "waypoint 2/6 → (14.0, 2.0, 4.0)" in panel.text
        top = app.query_one("#top", FormationView)
        assert top.next_wp is not None and top.path is not None and len(top.path) > 2
        assert "◎" in top.render().plain  # the next waypoint, drawn
        assert "◎" not in app.query_one("#side-view", FormationView).render().plain

        await type_goto(pilot, "20, 0, 5, 90")
        assert await settle(app, pilot, lambda: cmd.zenoh_calls)
        (c,) = cmd.zenoh_calls
        assert c.kind == "mission" and c.at_s == 5.0  # mission time + the 1 s lead
        (wp,) = json.loads(c.mission)["waypoint"]
        assert wp["centroid"] == [20.0, 0.0, 5.0] and wp["yaw_deg"] == 90.0
        assert "mission (all) published" in log_text(app)

        cmd.t = 6.0  # the go-to's plan is in force from 5 s
        app.refresh_data()
        await pilot.pause()
        assert "waypoint 1/1 → (20.0, 0.0, 5.0)" in panel.text
        assert top.next_wp is not None and list(top.next_wp) == [20.0, 0.0, 5.0]


async def test_a_bad_or_unflyable_goto_is_one_error_line_and_sends_nothing():
    cmd = FakeCommander()
    app = mission_app(cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await type_goto(pilot, "20 0")
        assert await settle(app, pilot, lambda: "go-to 20 0 refused" in log_text(app))
        assert "3 or 4 numbers" in log_text(app)
        await type_goto(pilot, "20 0 -3")  # under the floor: FormationSteer refuses it
        assert await settle(app, pilot, lambda: "go-to 20 0 -3 refused" in log_text(app))
        await pilot.press("g")
        await pilot.pause()
        await pilot.press("escape")  # cancelled: nothing, no line
        await pilot.pause()
        assert not isinstance(app.screen, InputScreen)
        assert log_text(app).count("refused") == 2
        assert cmd.zenoh_calls == []


async def test_without_a_mission_g_is_off_and_the_panel_hidden():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        assert not app.query_one(MissionPanel).display
        await pilot.press("g")
        await pilot.pause()
        assert not isinstance(app.screen, InputScreen)
        assert app.query_one("#top", FormationView).next_wp is None
    cmd = FakeCommander(up=False)  # a mission, but no Zenoh: g says why
    app = mission_app(cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("g")
        assert await settle(app, pilot, lambda: "go-to needs" in log_text(app))
        assert not isinstance(app.screen, InputScreen) and cmd.zenoh_calls == []
