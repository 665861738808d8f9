"""Export an SVG screenshot of the dashboard on the recorded state (docs/dashboard.svg).

python -m gcs.dashboard.screenshot docs/dashboard.svg --size 120x36
"""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path

from .app import DashboardApp
from .view.recorded import recorded_source


async def export(out: Path, width: int, height: int) -> Path:
    app = DashboardApp(recorded_source(), None, title="cube8 · recorded")
    async with app.run_test(size=(width, height)) as pilot:
        await pilot.pause()
        await pilot.pause()
        app.save_screenshot(filename=out.name, path=str(out.parent))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gcs.dashboard.screenshot")
    ap.add_argument("out", type=Path)
    ap.add_argument("--size", default="120x36", help="WIDTHxHEIGHT")
    a = ap.parse_args(argv)
    w, h = (int(x) for x in a.size.lower().split("x"))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    print(asyncio.run(export(a.out, w, h)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
