"""A swarm past MAVLink's 255 system ids (issue 44): generated and flown in process; refused
with one line wherever its agents would be MAVLink vehicles (a distributed run, the
simulator, the dashboard)."""

from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from cli_inproc import run_cli
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory as Ros2Decoder

from gcs.mission.inproc import run_inproc
from gcs.records import pair_table, topics
from gcs.records.export import load_record
from gcs.records.payloads import layout
from gcs.records.series import RunSeries
from gcs.records.writer import write_record
from gcs.scenario_gen import add_scenario_parser, build
from swarm_common.scenario.model import Scenario, dump_toml, parse_scenario
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


@pytest.fixture(scope="module")
def flown(big: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Scenario, Path]:
    """0.1 s of the swarm in process, its run folder and record written."""
    sc = parse_scenario(tomllib.loads(big.read_text()), "grid300")
    res = run_inproc(sc, "dcbf", duration=0.1)
    out = tmp_path_factory.mktemp("flown") / "run"
    res.save(out, sc)
    return sc, out


def test_it_flies_in_process(flown: tuple[Scenario, Path]) -> None:
    sc, out = flown
    assert sc.n == N and max(sc.ids) > MAVLINK_MAX_ID
    with np.load(out / "series.npz") as z:
        assert z["p"].shape == (5, N, 3)
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    assert metrics["collisions"] == 0
    assert metrics["min_distance_m"] > sc.controller.d_safe_m


def test_its_record_holds_the_closest_pairs(flown: tuple[Scenario, Path], big: Path,
                                            tmp_path: Path) -> None:
    """The record's /pairs, read by mcap's own ROS 2 decoder: 4 N pairs a step, the
    closest at that step over every pair, with their distance and barrier; its least
    barrier over every pair; the record and the run folder export the same pairs.csv."""
    sc, out = flown
    with np.load(out / "series.npz") as z:
        p, v, min_dist = z["p"], z["v"], z["min_dist"]
    tau, d = sc.controller.tau_safe_s, sc.controller.d_safe_m
    col = {int(i): c for c, i in enumerate(sc.ids)}
    with (out / "record.mcap").open("rb") as f:
        msgs = [m for _, _, _, m in make_reader(f, decoder_factories=[Ros2Decoder()])
                .iter_decoded_messages(topics=["/pairs"])]
    assert len(msgs) == len(p)
    i_all, j_all = np.triu_indices(N, 1)
    for k, m in enumerate(msgs):
        a = np.array([col[int(x)] for x in m.i])
        b = np.array([col[int(x)] for x in m.j])
        assert len(a) == 4 * N and np.all(a < b) and max(m.j) > MAVLINK_MAX_ID
        dist_all = np.linalg.norm(p[k, i_all] - p[k, j_all], axis=1)
        kth = np.sort(dist_all)[4 * N - 1]
        dist = np.linalg.norm(p[k, a] - p[k, b], axis=1)
        assert np.all(dist <= kth) and np.sum(dist_all < kth) <= 4 * N
        np.testing.assert_allclose(m.distance_m, dist, rtol=0, atol=1e-12)
        dp, dv = p[k, a] - p[k, b], v[k, a] - v[k, b]
        h = np.sum(dp * dp, axis=1) + 2 * tau * np.sum(dv * dp, axis=1) - d * d
        np.testing.assert_allclose(m.h_m2, h, rtol=0, atol=1e-9)
        dp, dv = p[k, i_all] - p[k, j_all], v[k, i_all] - v[k, j_all]
        h_all = np.sum(dp * dp, axis=1) + 2 * tau * np.sum(dv * dp, axis=1) - d * d
        assert m.min_h_m2 == pytest.approx(h_all.min(), abs=1e-9)
        assert m.min_distance_m == min_dist[k]
    assert run_cli("gcs", ["log", "export", str(out), "--format", "csv", "--scenario",
                           str(big), "--out", str(tmp_path / "a")]).returncode == 0
    assert run_cli("gcs", ["log", "export", str(out / "record.mcap"), "--format", "csv",
                           "--out", str(tmp_path / "b")]).returncode == 0
    rows = (tmp_path / "a" / "pairs.csv").read_bytes()
    assert rows.count(b"\n") == 1 + len(p) * 4 * N
    assert (tmp_path / "b" / "pairs.csv").read_bytes() == rows


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


def test_a_record_written_with_every_pair_still_reads(flown: tuple[Scenario, Path],
                                                      tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A record of more than 64 agents written before the closest-pairs rule (every pair
    at every step) reads back with every pair."""
    sc, out = flown
    with np.load(out / "series.npz") as z:
        ser = RunSeries(**{k: z[k] for k in z.files})
    doc = json.loads((out / "metrics.json").read_text())
    every = N * (N - 1) // 2
    with monkeypatch.context() as m:  # the rule before: every pair
        m.setattr(topics, "recorded_pair_count", lambda n: n * (n - 1) // 2)
        m.setattr(pair_table, "recorded_pair_count", lambda n: n * (n - 1) // 2)
        write_record(tmp_path, doc, ser, sc)
    ids, back, pairs = load_record(tmp_path / "record.mcap")
    assert ids == sorted(int(i) for i in sc.ids) and pairs.i.shape == (len(ser.t), every)
    i, j = np.triu_indices(N, 1)
    assert np.array_equal(pairs.i[2], i) and np.array_equal(pairs.j[2], j)
    np.testing.assert_allclose(pairs.distance_m[2], np.linalg.norm(
        ser.p[2, i] - ser.p[2, j], axis=1), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.min_dist, ser.min_dist)


def test_a_record_naming_an_unknown_agent_is_refused(flown: tuple[Scenario, Path],
                                                     tmp_path: Path) -> None:
    """A record whose /pairs names an id that has no agent topics (the message's layout
    otherwise right): one line, exit 2, nothing written."""
    _, out = flown
    bad = tmp_path / "bad.mcap"
    with (out / "record.mcap").open("rb") as f, bad.open("wb") as g:
        w = McapWriter(g)
        w.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for sch, ch, msg in make_reader(f).iter_messages():
            if ch.id not in channels:
                if sch is not None and sch.id not in schemas:
                    schemas[sch.id] = w.register_schema(sch.name, sch.encoding, sch.data)
                channels[ch.id] = w.register_channel(
                    ch.topic, ch.message_encoding, schemas[sch.id] if sch else 0)
            data = msg.data
            if ch.topic == "/pairs":
                fields = topics.pairs_fields(topics.recorded_pair_count(N), N)
                row = np.frombuffer(data, layout(fields)).copy()
                row["j"][0, 0] = N + 7  # no agent has this id
                data = row.tobytes()
            w.add_message(channels[ch.id], msg.log_time, data, msg.publish_time)
        w.finish()
    res = run_cli("gcs", ["log", "export", str(bad), "--format", "csv", "--out",
                          str(tmp_path / "csv")])
    assert res.returncode == 2, res
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "names an agent" in lines[0]
    assert not (tmp_path / "csv").exists()
