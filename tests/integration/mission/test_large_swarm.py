"""A swarm past MAVLink's 255 system ids (issue 44): generated and flown in process; refused
with one line wherever its agents would be MAVLink vehicles (a distributed run, the
simulator, the dashboard)."""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import pytest
from cli_inproc import run_cli

from gcs.mission.inproc import run_inproc
from gcs.scenario_gen import add_scenario_parser, build
from swarm_common.scenario.model import dump_toml, parse_scenario
from swarm_common.scenario.schema import MAVLINK_MAX_ID

N = 300


@pytest.fixture(scope="module")
def big(tmp_path_factory: pytest.TempPathFactory) -> Path:
    ap = argparse.ArgumentParser()
    add_scenario_parser(ap.add_subparsers(dest="command"))
    args = ap.parse_args(["scenario", "grid", "--agents", str(N), "--leaders", "4",
                          "--scramble", "1", "--duration", "2", "--deadline", "1"])
    doc, _, _ = build(args)
    path = tmp_path_factory.mktemp("big") / "grid300.toml"
    path.write_text(dump_toml(doc))
    return path


def test_it_flies_in_process(big: Path) -> None:
    sc = parse_scenario(tomllib.loads(big.read_text()), "grid300")
    assert sc.n == N and max(sc.ids) > MAVLINK_MAX_ID
    res = run_inproc(sc, "dcbf", duration=0.1)
    assert res.series.p.shape == (5, N, 3)
    assert res.metrics["collisions"] == 0
    assert res.metrics["min_distance_m"] > sc.controller.d_safe_m


@pytest.mark.parametrize(
    ("prog", "argv"),
    [("gcs", ["mission", "run"]),
     ("vehicle-sim", ["--lockstep", "--scenario"]),
     ("gcs", ["dashboard", "--no-zenoh", "--scenario"])],
)
def test_as_mavlink_vehicles_it_is_refused_in_one_line(big: Path, prog: str,
                                                       argv: list[str]) -> None:
    res = run_cli(prog, [*argv, str(big)])
    assert res.returncode == 2, res
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and f"1..{MAVLINK_MAX_ID}" in lines[0] and "--inproc" in lines[0]
