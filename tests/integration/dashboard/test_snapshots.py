"""Snapshot tests of the main screen (recorded state: deterministic)."""

from __future__ import annotations

from typing import Any

import pytest

from gcs.dashboard.app import DashboardApp
from gcs.dashboard.view.recorded import recorded_source


@pytest.mark.parametrize("size", [(80, 24), (160, 48)], ids=["80x24", "160x48"])
def test_main_screen(snap_compare, size):
    assert snap_compare(DashboardApp(recorded_source()), terminal_size=size)


class _SteadyToasts(DashboardApp):
    """The dashboard with its toasts kept until the screenshot: "t" shows one for 2 s, and
    on a loaded machine the modal's screenshot came after it had gone."""

    def notify(self, message: str, *args: Any, **kwargs: Any) -> None:
        kwargs["timeout"] = 3600.0
        super().notify(message, *args, **kwargs)


def test_emergency_stop_modal(snap_compare):
    assert snap_compare(_SteadyToasts(recorded_source()), press=["t", "x"],
                        terminal_size=(80, 24))
