"""``gcs dashboard --replay RUN`` on a short in-process cube8 run (its run folder and its
record.mcap): pilot tests of the keys, the closest approach on screen as metrics.json
says it, live commands refused; a bad RUN is one line and exit 2 before any app."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import CUBE8
from mcap.writer import Writer
from textual.geometry import Region

from gcs.dashboard.cli import add_dashboard_parser, build, run_dashboard
from gcs.dashboard.replay_app import ReplayApp
from gcs.dashboard.view.replay import fmt_dist
from gcs.dashboard.widgets import EventLog, ReplayBar
from gcs.mission.inproc import run_inproc
from swarm_common.scenario.model import load_scenario

DURATION_S = 3.0


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s cube8 run, written as ``gcs mission run --inproc --out`` writes it."""
    sc = load_scenario(CUBE8)
    out = tmp_path_factory.mktemp("replay") / "run"
    run_inproc(sc, duration=DURATION_S).save(out, sc)
    return out


def parse(*argv: str) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="gcs")
    add_dashboard_parser(ap.add_subparsers(dest="command", required=True))
    return ap.parse_args(["dashboard", *argv])


def replay(path: Path) -> ReplayApp:
    app, _, launch, _ = build(parse("--replay", str(path)))
    assert isinstance(app, ReplayApp) and launch is None
    return app


def on_screen(bar: ReplayBar) -> str:
    """The replay line as drawn (what fits in its width)."""
    return "".join(s.text for s in bar.render_lines(Region(0, 0, bar.size.width, 1)))


def metrics_min(run: Path) -> float:
    return float(json.loads((run / "metrics.json").read_text())["metrics"]["min_distance_m"])


@pytest.mark.asyncio
async def test_closest_approach_on_screen_is_the_runs_min_distance(run: Path) -> None:
    series = np.load(run / "series.npz")
    k_min = int(np.argmin(series["min_dist"]))
    app = replay(run)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("c")
        await pilot.pause()
        assert f"dmin {fmt_dist(metrics_min(run))}" in on_screen(app.query_one(ReplayBar))
        assert app.replay.cursor.frame == k_min
        assert f"{series['t'][k_min]:.2f}/" in app.sub_title and "paused" in app.sub_title
        await pilot.press("full_stop")  # one frame on, still held
        await pilot.pause()
        assert app.replay.cursor.frame == k_min + 1
        assert f"frame {k_min + 2}/{len(series['t'])}" in on_screen(app.query_one(ReplayBar))
        await pilot.press("a", "u")  # live commands: refused, one line each
        await pilot.pause()
        lines = app.query_one(EventLog).lines_text
        assert any("arm: live only" in ln for ln in lines)
        assert any("take-off: live only" in ln for ln in lines)
        await pilot.press("plus", "plus", "n")  # x4; the next event: the run's end
        await pilot.pause()
        assert app.replay.cursor.at_end and "x4" in app.sub_title
        assert any("end: safety verdict" in ln for ln in app.query_one(EventLog).lines_text)
        await pilot.press("p")  # back to the start: the log again up to there
        await pilot.pause()
        lines = app.query_one(EventLog).lines_text
        assert app.replay.cursor.frame == 0 and len(lines) == 1 and "start:" in lines[0]
        await pilot.press("space")  # plays on: the replay time moves with the wall clock
        for _ in range(100):
            if app.replay.cursor.frame > 0:
                break
            await pilot.pause(0.05)
        assert app.replay.cursor.frame > 0 and "x4" in app.sub_title


def test_the_record_alone_replays_the_same_run(run: Path) -> None:
    app = replay(run / "record.mcap")
    cur = app.replay.cursor
    assert cur.to_closest()
    assert f"dmin {fmt_dist(metrics_min(run))}" in cur.line_text()
    assert app.replay.run.doc["scenario"] == "cube8"


def foreign_mcap(path: Path) -> None:
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="other", library="test")
        sid = w.register_schema(name="Other", encoding="jsonschema", data=b"{}")
        cid = w.register_channel(topic="/other", message_encoding="json", schema_id=sid)
        w.add_message(channel_id=cid, log_time=0, data=b"{}", publish_time=0)
        w.finish()


def bad_runs(run: Path, tmp: Path) -> dict[str, tuple[list[str], str]]:
    """name -> (argv, a word the error names)."""
    half = tmp / "half"
    shutil.copytree(run, half)
    data = (half / "series.npz").read_bytes()
    (half / "series.npz").write_bytes(data[: len(data) // 2])
    cut = tmp / "cut.mcap"
    rec = (run / "record.mcap").read_bytes()
    cut.write_bytes(rec[: len(rec) // 2])
    foreign_mcap(tmp / "foreign.mcap")
    (tmp / "text.mcap").write_text("not a record\n")
    other = tmp / "other"
    shutil.copytree(run, other, ignore=shutil.ignore_patterns("record.mcap"))
    doc = json.loads((other / "metrics.json").read_text())
    (other / "metrics.json").write_text(json.dumps({**doc, "scenario": "no-such-scenario"}))
    empty = tmp / "empty"
    empty.mkdir()
    return {
        "missing": (["--replay", str(tmp / "nope")], "nope"),
        "empty folder": (["--replay", str(empty)], "metrics.json"),
        "truncated series": (["--replay", str(half)], "series.npz"),
        "truncated record": (["--replay", str(cut)], "cut.mcap"),
        "foreign record": (["--replay", str(tmp / "foreign.mcap")], "bearing-swarm"),
        "not MCAP": (["--replay", str(tmp / "text.mcap")], "MCAP"),
        "unknown scenario": (["--replay", str(other)], "--scenario"),
        "with --demo": (["--replay", str(run), "--demo"], "--demo"),
    }


def test_a_bad_run_is_one_line_and_exit_2(run: Path, tmp_path: Path, capsys) -> None:
    for name, (argv, word) in bad_runs(run, tmp_path).items():
        assert run_dashboard(parse(*argv)) == 2, name
        err = capsys.readouterr().err
        assert err.startswith("gcs dashboard: ") and err.count("\n") == 1, (name, err)
        assert word in err, (name, err)
