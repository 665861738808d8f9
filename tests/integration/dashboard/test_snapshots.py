"""Snapshot tests of the main screen (recorded state: deterministic)."""

from __future__ import annotations

import pytest

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.recorded import recorded_source


@pytest.mark.parametrize("size", [(80, 24), (160, 48)], ids=["80x24", "160x48"])
def test_main_screen(snap_compare, size):
    assert snap_compare(DashboardApp(recorded_source()), terminal_size=size)


def test_emergency_stop_modal(snap_compare):
    assert snap_compare(DashboardApp(recorded_source()), press=["t", "x"], terminal_size=(80, 24))
