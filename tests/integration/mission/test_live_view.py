"""The live view (issue 43 item 3; docs/records.md "Live view"): ``gcs mission run
--foxglove`` serves the record's channels on foxglove-sdk's WebSocket server while the run
goes. A real client (``websockets``, the Foxglove WebSocket protocol) subscribes and
decodes the messages with the protobuf schema the server advertises.

* a short distributed cube8 run: the advertised topics are the record's; every
  ``/world/tf`` received holds one transform per vehicle, finite, with a unit rotation,
  within reach of the vehicle's start position, and equal to the record's at that time;
* a LiveView in process: watched only while a client subscribes, attitudes as rotations,
  the onsets as ``/events``;
* a busy port: one line, exit 2, nothing run.
"""

from __future__ import annotations

import base64
import json
import math
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import CUBE8, ROOT, free_port_offset, wait_for
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoder
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Subprotocol

from gcs.mission.run_output import empty_series
from gcs.records import topics as tp
from gcs.records.channels import RecordContext
from gcs.records.live import LiveView
from swarm_common.scenario.model import load_scenario

pytestmark = pytest.mark.timeout(300)

# the SDK's protocol name, and the older name of the same protocol
SUBPROTOCOLS = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]
MESSAGE_DATA = 0x01  # server binary opcode: subscription id u32, log time u64, payload
URL = re.compile(r"live view: open (ws://\S+) in Foxglove")
TOL = 1e-9  # m: a live transform against the record's at the same time


class FoxgloveClient:
    """A Foxglove WebSocket client: the advertised channels, subscriptions, and the
    messages received as ``got[topic] = [(log time ns, payload)]``."""

    def __init__(self, url: str) -> None:
        self._open = connect(url, subprotocols=SUBPROTOCOLS, open_timeout=30)
        self.ws: ClientConnection = self._open.__enter__()
        self.channels: dict[str, dict[str, Any]] = {}
        self.subs: dict[int, str] = {}
        self.got: dict[str, list[tuple[int, bytes]]] = {}
        self.closed = False

    def pump(self, timeout: float = 0.2) -> None:
        """Take what arrives within ``timeout`` s (marks ``closed`` when the server goes)."""
        end = time.monotonic() + timeout
        while not self.closed and (left := end - time.monotonic()) > 0:
            try:
                m = self.ws.recv(timeout=left)
            except TimeoutError:
                return
            except ConnectionClosed:
                self.closed = True
                return
            if isinstance(m, str):
                doc = json.loads(m)
                if doc.get("op") == "advertise":
                    self.channels.update({c["topic"]: c for c in doc["channels"]})
            elif m[0] == MESSAGE_DATA:
                sub, log_ns = struct.unpack_from("<IQ", m, 1)
                self.got.setdefault(self.subs[sub], []).append((log_ns, bytes(m[13:])))

    def subscribe(self, topics: list[str], timeout: float = 60.0) -> None:
        assert wait_for(lambda: self.pump() or set(topics) <= set(self.channels), timeout)
        subs = [{"id": len(self.subs) + n + 1, "channelId": self.channels[t]["id"]}
                for n, t in enumerate(topics)]
        self.subs.update({s["id"]: t for s, t in zip(subs, topics, strict=True)})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def decoded(self, topic: str) -> list[tuple[int, Any]]:
        """The messages of a protobuf topic, decoded with the schema it was advertised with
        (a FileDescriptorSet, base64)."""
        ch = self.channels[topic]
        assert ch["encoding"] == "protobuf" and ch["schemaEncoding"] == "protobuf"
        pool = descriptor_pool.DescriptorPool()
        for f in descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"])).file:
            pool.Add(f)
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))
        return [(t, cls.FromString(data)) for t, data in self.got.get(topic, [])]

    def close(self) -> None:
        self._open.__exit__(None, None, None)


def _stamp_ns(ts: Any) -> int:
    return int(ts.seconds) * 10**9 + int(ts.nanos)


def _record_tf(path: Path) -> dict[int, np.ndarray]:
    """log time -> (N, 3) translations of the record's ``/world/tf``."""
    out = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoder()])
        for _, _, msg, obj in reader.iter_decoded_messages(topics=[tp.TF]):
            out[msg.log_time] = np.array([[x.translation.x, x.translation.y, x.translation.z]
                                          for x in obj.transforms])
    return out


@pytest.mark.slow
def test_a_distributed_run_is_served_live(tmp_path: Path) -> None:
    sc = load_scenario(CUBE8)
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "gcs.cli", "mission", "run", CUBE8, "--duration", "2",
         "--processes", "2", "--port-offset", str(free_port_offset()), "--out", str(out),
         "--foxglove", "--foxglove-port", "0"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr or []), daemon=True)
    reader.start()
    client = None
    try:
        assert wait_for(lambda: any(URL.search(ln) for ln in lines) or proc.poll() is not None,
                        120.0), "no live view line"
        url = next((m.group(1) for ln in lines if (m := URL.search(ln))), None)
        assert url is not None and url.startswith("ws://127.0.0.1:"), "".join(lines)[-2000:]
        client = FoxgloveClient(url)
        client.subscribe([tp.TF])
        # until the run ends: its server stops and closes the connection
        assert wait_for(lambda: client.pump(1.0) or client.closed, 240.0)
        assert proc.wait(60) == 0, "".join(lines)[-2000:]
    finally:
        if client is not None:
            client.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    reader.join(5)
    # the record's topics and schemas, by name
    assert {t: c["schemaName"] for t, c in client.channels.items()} == tp.all_topics(sc.ids)
    tf = client.decoded(tp.TF)
    assert tf, "no /world/tf received"
    record = _record_tf(out / "record.mcap")
    p0, v0 = sc.initial_positions(), sc.initial_velocities()
    # every vehicle within reach of its start: |p − p0 − v0 t| <= a t² / 2, a twice what
    # thrust and gravity give (the disturbances' share is far smaller)
    a_max = 2 * (sc.vehicle.thrust_max_n / sc.vehicle.mass_kg + sc.vehicle.gravity_mps2)
    frames = [tp.vehicle_frame(i) for i in sc.ids]
    for log_ns, msg in tf:
        assert [x.child_frame_id for x in msg.transforms] == frames
        assert all(x.parent_frame_id == tp.WORLD_FRAME for x in msg.transforms)
        assert all(_stamp_ns(x.timestamp) == log_ns for x in msg.transforms)
        p = np.array([[x.translation.x, x.translation.y, x.translation.z]
                      for x in msg.transforms])
        q = np.array([[x.rotation.x, x.rotation.y, x.rotation.z, x.rotation.w]
                      for x in msg.transforms])
        assert np.isfinite(p).all() and np.isfinite(q).all()
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
        t = log_ns * 1e-9
        assert np.all(np.linalg.norm(p - p0 - v0 * t, axis=1) <= 0.5 * a_max * t * t + 1e-3)
        np.testing.assert_allclose(p, record[log_ns], rtol=0, atol=TOL)


def test_a_live_view_in_process_serves_attitudes_and_onsets() -> None:
    c = RecordContext.bare(3)
    view = LiveView(c, {"scenario": "three", "method": "dcbf", "seed": 1}, port=0)
    try:
        assert not view.watched()
        client = FoxgloveClient(view.url)
        client.subscribe([tp.TF, tp.EVENTS])
        ch = view.channels
        assert wait_for(lambda: client.pump() or (ch.tf.has_sinks() and ch.events.has_sinks()),
                        30.0)
        assert view.watched()
        s = empty_series(np.array([0.0, 0.02]), 3)
        s.p[:] = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0]]
        s.fallback[1, 2] = True  # agent 3's QP falls back at the second row
        att = np.zeros((2, 3, 3))
        att[:, 0, 0] = 0.2  # roll of vehicle 1
        att[:, 1, 2] = 0.5  # yaw of vehicle 2
        view.publish(s, att)
        assert wait_for(lambda: client.pump() or (len(client.got.get(tp.TF, [])) == 2
                                                  and len(client.got.get(tp.EVENTS, [])) == 2),
                        30.0)
        tf = client.decoded(tp.TF)
        assert [t for t, _ in tf] == [0, 20_000_000]
        r = [(x.rotation.x, x.rotation.y, x.rotation.z, x.rotation.w)
             for x in tf[0][1].transforms]
        np.testing.assert_allclose(r[0], (math.sin(0.1), 0, 0, math.cos(0.1)), atol=1e-9)
        np.testing.assert_allclose(r[1], (0, 0, math.sin(0.25), math.cos(0.25)), atol=1e-9)
        np.testing.assert_allclose(r[2], (0, 0, 0, 1), atol=0)
        logs = [(t, m.name, m.message) for t, m in client.decoded(tp.EVENTS)]
        assert logs == [(0, "run", "start: scenario three, method dcbf, seed 1"),
                        (20_000_000, "agent/3", "QP degraded: fallback")]
        client.close()
        assert wait_for(lambda: not view.watched(), 30.0)  # nobody left: publishing is free
    finally:
        view.close()


@pytest.mark.slow
def test_a_failed_run_ends_its_live_view_with_an_error_event() -> None:
    """A run that stops without its document (a dead agent worker): the view's last event
    says so, at ERROR, at the last time published, and no verdict follows."""
    from gcs.records.events import ERROR

    view = LiveView(RecordContext.bare(2), {"scenario": "two", "method": "dcbf", "seed": 1},
                    port=0)
    try:
        client = FoxgloveClient(view.url)
        client.subscribe([tp.EVENTS])
        assert wait_for(lambda: client.pump() or view.channels.events.has_sinks(), 30.0)
        s = empty_series(np.array([0.0, 0.02, 0.04]), 2)
        s.p[:] = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]
        view.publish(s)
        view.fail("agent worker agents 1-1 died (exit -9)")
        assert wait_for(lambda: client.pump() or len(client.got.get(tp.EVENTS, [])) == 2,
                        30.0)
        logs = [(t, m.level, m.name, m.message) for t, m in client.decoded(tp.EVENTS)]
        assert logs[0][3].startswith("start: scenario two")
        assert logs[1] == (40_000_000, ERROR, "run",
                           "failed: agent worker agents 1-1 died (exit -9)")
        client.close()
    finally:
        view.close()


def test_a_busy_port_is_one_line_and_exit_2(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = subprocess.run(
            [sys.executable, "-m", "gcs.cli", "--log-level", "error", "mission", "run", CUBE8,
             "--inproc",
             "--duration", "1", "--out", str(tmp_path / "run"), "--foxglove",
             "--foxglove-port", str(port)],
            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("gcs mission run: live view on 127.0.0.1:") and str(port) in lines[0]
    assert not (tmp_path / "run").exists()  # nothing ran
