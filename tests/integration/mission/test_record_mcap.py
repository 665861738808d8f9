"""The MCAP record of a cube8 run (issue 43; docs/records.md), read back with the ``mcap``
reader and independent decoders (``mcap-protobuf-support`` for Foxglove's protobuf
schemas, ``mcap-ros2-support`` for the ROS 2 messages): every channel and schema, one
message (or transform) per vehicle per step, the poses and the safety filter's report
(status, active rows, slacks, u_nom, ‖u − u_nom‖) equal to ``series.npz`` to 1e-9, the
audit's MAVLink commands as events; ``gcs log export`` round trips, an older record too;
bad input is one line and exit 2, nothing written."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import CUBE8, ROOT
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoder
from mcap_ros2.decoder import DecoderFactory as Ros2Decoder

from gcs.cli import main as gcs_main
from gcs.records import topics as tp
from gcs.records import writer
from gcs.records.export import VEHICLE_COLUMNS, load_record, read_vehicle_csv
from gcs.records.series import UNKNOWN_STATUS, RunSeries
from gcs.records.writer import write_record
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario

pytestmark = pytest.mark.integration

TOL = 1e-9  # m: poses read back against series.npz (the tolerance)
DURATION_S = 5.0


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "run"
    subprocess.run([sys.executable, "-m", "gcs.cli", "mission", "run", str(CUBE8), "--inproc",
                    "--duration", str(DURATION_S), "--out", str(out)], cwd=ROOT, check=True,
                   capture_output=True, timeout=120)
    d = np.load(out / "series.npz")
    ser = RunSeries(**{k: d[k] for k in d.files})
    write_record(out, json.loads((out / "metrics.json").read_text()), ser,
                 load_scenario(str(CUBE8)))
    return out


@pytest.fixture(scope="module")
def series(run: Path) -> RunSeries:
    d = np.load(run / "series.npz")
    return RunSeries(**{k: d[k] for k in d.files})


@pytest.fixture(scope="module")
def decoded(run: Path) -> dict[str, list[tuple[int, object]]]:
    """topic -> [(log time ns, decoded message)] in file order."""
    out: dict[str, list[tuple[int, object]]] = {}
    with (run / "record.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoder(), Ros2Decoder()])
        for _, ch, msg, obj in reader.iter_decoded_messages(log_time_order=False):
            out.setdefault(ch.topic, []).append((msg.log_time, obj))
    return out


def _ns(t: np.ndarray) -> list[int]:
    return np.round(t * 1e9).astype(np.int64).tolist()


def test_every_channel_and_schema(run: Path) -> None:
    sc = load_scenario(str(CUBE8))
    with (run / "record.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    got = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
    assert got == tp.all_topics(list(sc.ids))
    enc = {summary.schemas[ch.schema_id].name: (summary.schemas[ch.schema_id].encoding,
                                                 ch.message_encoding)
           for ch in summary.channels.values()}
    assert enc["foxglove.FrameTransforms"] == ("protobuf", "protobuf")
    assert enc[tp.ESTIMATE_SCHEMA] == ("ros2msg", "cdr")
    assert summary.statistics is not None and summary.statistics.message_count > 0


def test_transforms_one_per_vehicle_per_step_equal_series(decoded, series: RunSeries) -> None:
    sc = load_scenario(str(CUBE8))
    tf = decoded[tp.TF]
    assert [t for t, _ in tf] == _ns(series.t)
    frames = [tp.vehicle_frame(i) for i in sc.ids]
    for k, (t_ns, msg) in enumerate(tf):
        assert [x.child_frame_id for x in msg.transforms] == frames
        assert all(x.parent_frame_id == tp.WORLD_FRAME for x in msg.transforms)
        assert {x.timestamp.seconds * 10**9 + x.timestamp.nanos for x in msg.transforms} == {t_ns}
        p = np.array([[x.translation.x, x.translation.y, x.translation.z]
                      for x in msg.transforms])
        np.testing.assert_allclose(p, series.p[k], rtol=0, atol=TOL)


def test_agent_topics_one_per_step_equal_series(decoded, series: RunSeries) -> None:
    sc = load_scenario(str(CUBE8))
    ns = _ns(series.t)
    for a, i in enumerate(sc.ids):
        est, qp = decoded[tp.estimate_topic(i)], decoded[tp.qp_topic(i)]
        assert [t for t, _ in est] == ns and [t for t, _ in qp] == ns
        for name, field in (("p_m", "p"), ("v_m_s", "v"), ("p_est_m", "z1"),
                            ("v_est_m_s", "z2"), ("d_est_m_s2", "lumped_est"),
                            ("p_des_m", "p_des")):
            got = np.array([getattr(m, name) for _, m in est])
            np.testing.assert_allclose(got, getattr(series, field)[:, a], rtol=0, atol=TOL)
        err = np.array([m.p_err_m for _, m in est])
        np.testing.assert_allclose(err, np.linalg.norm(series.z1[:, a] - series.p[:, a],
                                                       axis=1), rtol=0, atol=TOL)
        np.testing.assert_array_equal([m.h_min_m2 for _, m in qp], series.h_min[:, a])
        np.testing.assert_array_equal([m.degraded for _, m in qp], series.fallback[:, a])
        np.testing.assert_array_equal([m.alarms for _, m in qp], series.alarms[:, a])


def test_filter_report_on_the_qp_topics_equals_series(decoded, series: RunSeries) -> None:
    """The QP's status, active rows and their kinds, the slacks, u_nom and ‖u − u_nom‖ of
    every agent and step, read back, equal the series (the followers' QP binds some
    rows in these 5 s of cube8; the leaders have no filter: no correction)."""
    sc = load_scenario(str(CUBE8))
    for a, i in enumerate(sc.ids):
        qp = [m for _, m in decoded[tp.qp_topic(i)]]
        for name, field in (("u_nom_m_s2", "u_nom"), ("correction_m_s2", "u_corr"),
                            ("clf_slack_m_s2", "clf_slack"), ("relax_m_s2", "qp_relax")):
            got = np.array([getattr(m, name) for m in qp])
            np.testing.assert_allclose(got, getattr(series, field)[:, a], rtol=0, atol=TOL)
        for name, field in (("qp_status", "qp_status"), ("active_rows", "qp_active"),
                            ("active_kinds", "qp_kinds")):
            np.testing.assert_array_equal([getattr(m, name) for m in qp],
                                          getattr(series, field)[:, a])
    assert (series.qp_status != UNKNOWN_STATUS).all()  # in process: every step's status
    f = [sc.index_of(i) for i in sc.follower_ids]
    lead = [sc.index_of(i) for i in sc.leader_ids]
    assert series.qp_active[:, f].max() > 0 and (series.u_corr[:, f] > 1e-3).any()
    assert (series.qp_active[:, lead] == 0).all() and (series.u_corr[:, lead] == 0).all()
    np.testing.assert_array_equal(series.u_nom[:, lead], series.u[:, lead])
    # a step with active rows is a solved QP, and a QP that was not solved has none
    solved = series.qp_status == 1
    assert not (series.qp_active[~solved] > 0).any()


def test_audit_commands_are_events(run: Path, series: RunSeries, tmp_path: Path) -> None:
    """MAVLink commands of ``metrics.json``'s audit (a distributed run's; in process there
    are none) are ``/events`` lines at their times: the mode asked for, refused ones as
    warnings; a Zenoh command too."""
    doc = json.loads((run / "metrics.json").read_text())
    rec = {"vehicle": 3, "link": "api", "signed": True, "params": [129.0, 6.0, 0.0],
           "command": "MAV_CMD_DO_SET_MODE", "result": "MAV_RESULT_ACCEPTED",
           "accepted": True, "reason": ""}
    doc["audit"] = {"mavlink": [
        {**rec, "t": 0.5},
        {**rec, "t": 1.0, "vehicle": 4, "params": [129.0, 4.0, 6.0],
         "result": "MAV_RESULT_DENIED", "accepted": False, "reason": "not armed"}],
        "zenoh": [{"t": 2.0, "key": "swarm/cube8/cmd/land", "kind": "land", "agent": 0,
                   "fields": {"at_s": 2.0}}]}
    shutil.copy(run / "series.npz", tmp_path / "series.npz")
    write_record(tmp_path, doc, series, load_scenario(str(CUBE8)))
    with (tmp_path / "record.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoder()])
        ev = [(m.log_time, o) for _, ch, m, o in reader.iter_decoded_messages(
            topics=[tp.EVENTS])]
    lines = {(o.name, o.message, int(o.level)): t for t, o in ev}
    assert lines[("agent/3", "MAVLink set mode OFFBOARD: MAV_RESULT_ACCEPTED [link api]",
                  2)] == 500_000_000
    assert lines[("agent/4", "MAVLink set mode LAND: MAV_RESULT_DENIED (not armed) "
                  "[link api]", 3)] == 1_000_000_000
    assert lines[("gcs", "command land to all agents at 2 s", 2)] == 2_000_000_000


def test_a_record_written_before_the_filter_report_still_exports(
        series: RunSeries, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A record of the first QP message version (no filter report) reads back with the
    report unknown, the rest as before."""
    doc = {"scenario": "cube8", "method": "dcbf", "seed": 1, "metrics": {}}
    with monkeypatch.context() as m:
        m.setattr(tp, "QP_FIELDS", tp.QP_FIELDS_V1)
        write_record(tmp_path, doc, series, load_scenario(str(CUBE8)))
    ids, old, _ = load_record(tmp_path / "record.mcap")
    assert ids == list(load_scenario(str(CUBE8)).ids)
    np.testing.assert_array_equal(old.u, series.u)
    assert (old.qp_status == UNKNOWN_STATUS).all() and np.isnan(old.u_corr).all()


def test_pairs_distance_and_barrier(decoded, series: RunSeries) -> None:
    sc = load_scenario(str(CUBE8))
    tau, d = sc.controller.tau_safe_s, sc.controller.d_safe_m
    pairs = decoded[tp.PAIRS]
    assert len(pairs) == len(series.t)
    for k in (0, len(pairs) // 2, len(pairs) - 1):
        m = pairs[k][1]
        col = {int(i): c for c, i in enumerate(sc.ids)}
        for n, (i, j) in enumerate(zip(m.i, m.j, strict=True)):  # a loop, not pair_barrier
            dp = series.p[k, col[i]] - series.p[k, col[j]]
            dv = series.v[k, col[i]] - series.v[k, col[j]]
            assert abs(m.distance_m[n] - float(np.sqrt(dp @ dp))) < TOL
            assert abs(m.h_m2[n] - (dp @ dp + 2 * tau * (dv @ dp) - d * d)) < TOL
        assert m.min_h_m2 == min(m.h_m2)
        assert m.min_distance_m == series.min_dist[k]
    assert len(pairs[0][1].i) == sc.n * (sc.n - 1) // 2


def test_scene_vehicles_and_bearings(decoded, series: RunSeries) -> None:
    sc = load_scenario(str(CUBE8))
    form = formation_from_scenario(sc)
    scene = decoded[tp.SCENE]
    first = {e.id for e in scene[0][1].entities}
    assert {f"vehicle/{i}" for i in sc.ids} <= first
    sensed = sum(len(form.sensed[f]) for f in form.follower_idx)
    bearings = [(t, m) for t, m in scene if m.entities[0].id == "bearings"]
    assert len(bearings) == len(range(0, len(series.t), 5))  # 10 Hz of a 50 Hz run
    ns = _ns(series.t)
    for t, m in bearings[:3]:
        k = ns.index(t)
        pts = np.array([[q.x, q.y, q.z] for q in m.entities[0].lines[0].points])
        assert len(pts) == 2 * sensed
        # every end is some vehicle's true position at that step
        dist = np.linalg.norm(pts[:, None] - series.p[k][None], axis=2).min(axis=1)
        assert dist.max() < TOL


def test_desired_and_events(decoded, series: RunSeries) -> None:
    des = decoded[tp.DESIRED]
    steps = range(0, len(series.t), 5)  # 10 Hz of a 50 Hz run
    assert [t for t, _ in des] == [_ns(series.t)[k] for k in steps]
    got = np.array([[p.position.x, p.position.y, p.position.z] for p in des[-1][1].poses])
    np.testing.assert_allclose(got, series.p_des[steps[-1]], rtol=0, atol=TOL)
    ev = [m for _, m in decoded[tp.EVENTS]]
    assert ev[0].message.startswith("start: scenario cube8")
    assert ev[-1].message.startswith("end: safety verdict")


def test_record_size_per_second(run: Path) -> None:
    # 60 s must stay under 20 MB: the 5 s record scaled (its fixed part counts 12 times)
    assert (run / "record.mcap").stat().st_size * 60 / DURATION_S < 20e6


def test_csv_export_round_trips(run: Path, series: RunSeries, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    sc = load_scenario(str(CUBE8))
    assert gcs_main(["log", "export", str(run), "--format", "csv", "--out",
                     str(tmp_path / "a")]) == 0
    assert gcs_main(["log", "export", str(run / "record.mcap"), "--format", "csv", "--out",
                     str(tmp_path / "b")]) == 0
    for a, i in enumerate(sc.ids):
        cols = read_vehicle_csv(tmp_path / "a" / f"vehicle_{i}.csv")
        np.testing.assert_array_equal(cols["t_s"], series.t)
        for field, names in VEHICLE_COLUMNS:
            want = np.asarray(getattr(series, field))[:, a].reshape(len(series.t), -1)
            got = np.column_stack([cols[n] for n in names])
            np.testing.assert_array_equal(got, want.astype(float), err_msg=field)
        assert (tmp_path / "b" / f"vehicle_{i}.csv").read_bytes() == \
            (tmp_path / "a" / f"vehicle_{i}.csv").read_bytes()
    pairs = np.loadtxt(tmp_path / "a" / "pairs.csv", delimiter=",", skiprows=1)
    assert pairs.shape == (len(series.t) * 28, 5)
    ids = list(sc.ids)
    for row in pairs[7 * 28: 8 * 28]:  # step 7: every pair once, distance from the series
        k, c1, c2 = 7, ids.index(int(row[1])), ids.index(int(row[2]))
        assert row[0] == series.t[k] and c1 < c2
        assert row[3] == pytest.approx(np.linalg.norm(series.p[k, c1] - series.p[k, c2]),
                                       abs=TOL)
    assert (tmp_path / "b" / "pairs.csv").read_bytes() == \
        (tmp_path / "a" / "pairs.csv").read_bytes()


def test_mcap_conversion_of_an_old_run(run: Path, tmp_path: Path) -> None:
    old = tmp_path / "old"
    old.mkdir()
    for f in ("metrics.json", "series.npz"):
        shutil.copy(run / f, old / f)
    assert gcs_main(["log", "export", str(old), "--format", "mcap", "--out", str(old)]) == 0
    assert gcs_main(["log", "export", str(old / "record.mcap"), "--format", "csv", "--out",
                     str(tmp_path / "c")]) == 0
    assert gcs_main(["log", "export", str(run), "--format", "csv", "--out",
                     str(tmp_path / "d")]) == 0
    for f in ("vehicle_3.csv", "pairs.csv"):
        assert (tmp_path / "c" / f).read_bytes() == (tmp_path / "d" / f).read_bytes()


def _foreign_mcap(path: Path) -> Path:
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("other", "jsonschema", b"{}")
        cid = w.register_channel("/other", "json", sid)
        w.add_message(cid, log_time=0, data=b"{}", publish_time=0)
        w.finish()
    return path


@pytest.mark.parametrize("kind", ["truncated", "text", "foreign", "no_series", "dir_as_file",
                                  "out_is_file"])
def test_bad_input_one_line_exit_2(kind: str, run: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    fmt = "csv"
    if kind == "truncated":
        data = (run / "record.mcap").read_bytes()
        src = tmp_path / "t.mcap"
        src.write_bytes(data[: len(data) // 2])
    elif kind == "text":
        src = tmp_path / "x.mcap"
        src.write_text("not an mcap\n")
    elif kind == "foreign":
        src = _foreign_mcap(tmp_path / "f.mcap")
    elif kind == "no_series":
        src = tmp_path / "r"
        src.mkdir()
        shutil.copy(run / "metrics.json", src / "metrics.json")
        fmt = "mcap"
    elif kind == "dir_as_file":
        src = tmp_path / "d.mcap"
        src.mkdir()
    else:
        src = run
        out.write_text("a file")
    capsys.readouterr()
    rc = gcs_main(["log", "export", str(src), "--format", fmt, "--out", str(out)])
    err = capsys.readouterr()
    assert rc == 2
    assert err.out == ""
    assert err.err.count("\n") == 1 and err.err.startswith("gcs log export: ")
    assert "Traceback" not in err.err
    if kind != "out_is_file":
        assert not out.exists()
    else:
        assert out.read_text() == "a file"


def test_a_record_built_in_chunks_is_the_same_file(run: Path, series: RunSeries,
                                                   tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """write_mcap builds the ROS 2 bodies CHUNK_STEPS steps at a time: chunks of 7 steps
    (a boundary inside the bearing lines' period) and one chunk of every step write the
    same bytes."""
    doc = json.loads((run / "metrics.json").read_text())
    sc = load_scenario(str(CUBE8))
    files = []
    for steps in (7, 10**9):
        monkeypatch.setattr(writer, "CHUNK_STEPS", steps)
        out = tmp_path / str(steps)
        out.mkdir()
        files.append(write_record(out, doc, series, sc).read_bytes())
    assert files[0] == files[1] and len(files[0]) > 10_000
