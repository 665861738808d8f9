"""Pilot tests: every key binding and the command palette, on a recorded state."""

from __future__ import annotations

import pytest

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.mavlink_gcs import CommandResult
from gcs.dashboard.px4modes import COMMANDS
from gcs.dashboard.view.recorded import recorded_source
from gcs.dashboard.widgets import ChoiceScreen, ConfirmScreen, EventLog, VehicleTable
from swarm_common.enums import Method

pytestmark = pytest.mark.asyncio


class FakeCommander:
    def __init__(self, result: int | None = 0):
        self.mav_calls: list[tuple[int, str]] = []
        self.zenoh_calls: list = []
        self.result = result

    async def mav(self, sysid: int, key: str) -> CommandResult:
        self.mav_calls.append((sysid, key))
        spec = COMMANDS[key]
        return CommandResult(sysid, spec.command, spec.label, self.result, 1, 0.01)

    def zenoh(self, cmd) -> str:
        self.zenoh_calls.append(cmd)
        return f"swarm/test/cmd/{cmd.kind}"


async def settle(app, pilot, pred=None, tries=100):
    for _ in range(tries):
        await app.workers.wait_for_complete()
        await pilot.pause()
        if pred is None or pred():
            return True
    return False


def log_text(app) -> str:
    return "\n".join(app.query_one(EventLog).lines_text)


@pytest.mark.parametrize(
    "key,action",
    [("a", "arm"), ("d", "disarm"), ("f", "offboard"), ("h", "hold"), ("l", "land")],
)
async def test_mav_bindings_selected_vehicle(key, action):
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("down", "down")  # select vehicle 3
        assert app.query_one(VehicleTable).selected_id == 3
        await pilot.press(key)
        assert await settle(app, pilot, lambda: cmd.mav_calls)
        assert cmd.mav_calls == [(3, action)]
        assert await settle(app, pilot, lambda: "ACCEPTED" in log_text(app))
        assert f"#3 {COMMANDS[action].label}: ACCEPTED" in log_text(app)


async def test_toggle_target_all_and_failed_ack_is_logged():
    cmd = FakeCommander(result=None)  # every command times out
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t")
        assert app.target_all
        await pilot.press("a")
        assert isinstance(app.screen, ConfirmScreen)  # a group command: its targets first
        assert "#1 #2 #3 #4 #5 #6 #7 #8" in app.screen.question and cmd.mav_calls == []
        await pilot.press("y")
        assert await settle(app, pilot, lambda: len(cmd.mav_calls) == 8)
        assert sorted(i for i, _ in cmd.mav_calls) == list(range(1, 9))
        assert await settle(app, pilot, lambda: log_text(app).count("TIMEOUT") == 8)
        await pilot.press("t")
        assert not app.target_all


async def test_estop_confirm_and_cancel():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("x")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("n")
        assert not isinstance(app.screen, ConfirmScreen)
        assert await settle(app, pilot, lambda: "cancelled" in log_text(app))
        assert cmd.mav_calls == []
        await pilot.press("x")
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("escape")
        assert cmd.mav_calls == []
        await pilot.press("x")
        await pilot.press("y")
        assert await settle(app, pilot, lambda: cmd.mav_calls)
        assert cmd.mav_calls == [(1, "terminate")]
        assert await settle(app, pilot, lambda: "emergency stop: ACCEPTED" in log_text(app))


async def test_estop_button_click():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "x")
        await pilot.click("#yes")
        assert await settle(app, pilot, lambda: len(cmd.mav_calls) == 8)
        assert {k for _, k in cmd.mav_calls} == {"terminate"}


async def test_method_switch():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("m")
        assert isinstance(app.screen, ChoiceScreen)
        order = [str(m) for m in Method]  # the picker lists the methods in this order
        downs = ["down"] * (order.index("apf") - order.index("rcbf"))
        await pilot.press(*downs, "enter")  # rcbf -> apf
        assert await settle(app, pilot, lambda: cmd.zenoh_calls)
        c = cmd.zenoh_calls[-1]
        assert (c.kind, c.method, c.agent) == ("method", "apf", 1)
        await pilot.press("t", "m", *(["down"] * order.index("none")), "enter")  # all -> none
        assert await settle(app, pilot, lambda: len(cmd.zenoh_calls) == 2)
        c = cmd.zenoh_calls[-1]
        assert (c.kind, c.method, c.agent) == ("method", "none", 0)
        await pilot.press("m", "escape")
        assert len(cmd.zenoh_calls) == 2
        assert "method none (all) published" in log_text(app)


async def test_outage_injection():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "o")
        assert isinstance(app.screen, ChoiceScreen)
        await pilot.press("down", "down", "enter")  # 2 s
        assert await settle(app, pilot, lambda: cmd.zenoh_calls)
        c = cmd.zenoh_calls[-1]
        assert (c.kind, c.duration_s, c.agent) == ("outage", 2.0, 0)
        assert "outage 2 s (all) published" in log_text(app)


async def test_zenoh_off_is_logged_not_fatal():
    class NoZenoh(FakeCommander):
        def zenoh(self, cmd):
            raise RuntimeError("zenoh is off")

    app = DashboardApp(recorded_source(), NoZenoh())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("o", "enter")
        assert await settle(app, pilot, lambda: "zenoh is off" in log_text(app))


async def test_read_only_without_commander():
    app = DashboardApp(recorded_source(), None)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("a")
        assert await settle(app, pilot, lambda: "read-only" in log_text(app))


async def test_command_palette_arm_all():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("ctrl+p")
        await pilot.press(*"arm: all vehicles")
        await settle(app, pilot, tries=5)
        await pilot.press("enter")
        assert await settle(app, pilot, lambda: isinstance(app.screen, ConfirmScreen))
        await pilot.press("y")
        assert await settle(app, pilot, lambda: len(cmd.mav_calls) == 8)
        assert {k for _, k in cmd.mav_calls} == {"arm"}


async def test_group_command_cancelled_sends_nothing():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("t", "f")
        assert isinstance(app.screen, ConfirmScreen)
        assert "8 vehicles" in app.screen.question
        await pilot.press("n")
        assert await settle(app, pilot, lambda: "cancelled" in log_text(app))
        assert cmd.mav_calls == []
        await pilot.press("t", "f")  # one vehicle again: no question, at once
        assert await settle(app, pilot, lambda: cmd.mav_calls == [(1, "offboard")])


async def test_command_palette_method():
    cmd = FakeCommander()
    app = DashboardApp(recorded_source(), cmd)
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("ctrl+p")
        await pilot.press(*"method apf")
        await settle(app, pilot, tries=5)
        await pilot.press("enter")
        assert await settle(app, pilot, lambda: cmd.zenoh_calls)
        assert cmd.zenoh_calls[-1].method == "apf"


async def test_quit():
    app = DashboardApp(recorded_source(), FakeCommander())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("q")
        await pilot.pause()
    assert app.return_code in (0, None)
    assert not app.is_running


async def test_recorded_rows_and_silent_vehicle():
    app = DashboardApp(recorded_source(), None)
    async with app.run_test(size=(80, 24)):
        v = app.view
        assert v.row(6).link_lost and v.row(6).failsafe == "LINK"
        assert v.row(8).status_missing and v.row(8).failsafe == "NO-OFB"
        assert app.query_one(EventLog).count >= 10


async def test_navigation_menu_sends_a_checked_mission_command():
    """n (gcs.dashboard.navigate) on a mission scenario: a step north goes out as one Zenoh
    "mission" command from the swarm's mission time + 1 s; without a mission it is refused
    with a line in the event log and nothing is sent."""
    import json
    from pathlib import Path

    from dashboard_fakes import FakeCommander as ZenohCommander

    from gcs.formation.steer import FormationSteer
    from swarm_common.scenario.model import load_scenario

    root = Path(__file__).resolve().parents[3]
    cmd = ZenohCommander()  # Zenoh up, mission time 4 s
    app = DashboardApp(recorded_source(), cmd,
                       steer=FormationSteer(load_scenario(root / "scenarios" / "course8.toml")))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("n")
        assert isinstance(app.screen, ChoiceScreen)
        await pilot.press("enter")  # the first choice: north
        assert await settle(app, pilot, lambda: cmd.zenoh_calls)
        c = cmd.zenoh_calls[-1]
        assert c.kind == "mission" and c.at_s == 5.0
        assert json.loads(c.mission)["waypoint"][0]["centroid"] == [2.0, 4.0, 4.0]
    plain = ZenohCommander()
    app = DashboardApp(recorded_source(), plain)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("n")
        assert await settle(app, pilot, lambda: "navigation needs" in
                            "\n".join(app.query_one(EventLog).lines_text))
        assert plain.zenoh_calls == []
