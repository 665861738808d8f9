"""Zenoh authentication and access control of a swarm (real sessions on 127.0.0.1).

The router is opened with the generated ``router.json5`` (user/password dictionary and
ACL, :func:`swarm_common.zenoh_session.write_swarm_security`); clients dial it with or
without credentials. What reaches a subscriber on the router session shows what the
router admitted.
"""

from __future__ import annotations

import stat
import threading
import time
from pathlib import Path

import pytest
from conftest import free_port_offset

from swarm_common import wire
from swarm_common.zenoh_session import (
    DEFAULT_ZENOH_PORT,
    GCS_USER,
    SIM_USER,
    agent_user,
    open_session,
    write_swarm_security,
)

pytestmark = pytest.mark.timeout(120)
SWARM = "acl"


class Sink:
    """Keys (and key, payload pairs) a subscriber received."""

    def __init__(self) -> None:
        self.keys: list[str] = []
        self.got: set[tuple[str, bytes]] = set()
        self.lock = threading.Lock()

    def __call__(self, sample: object) -> None:
        key = str(sample.key_expr)  # type: ignore[attr-defined]
        with self.lock:
            self.keys.append(key)
            self.got.add((key, sample.payload.to_bytes()))  # type: ignore[attr-defined]

    def wait_for(self, key: str, timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if key in self.keys:
                    return True
            time.sleep(0.05)
        return False


@pytest.fixture()
def secured(tmp_path: Path):
    sec = write_swarm_security(tmp_path / "zenoh", SWARM, [1, 2])
    ep = f"tcp/127.0.0.1:{DEFAULT_ZENOH_PORT + free_port_offset()}"
    router = open_session("router", listen=[ep], config_file=sec.router)
    sink = Sink()
    sub = router.declare_subscriber("swarm/**", sink)  # other swarms too
    opened = []

    def client(user: str | None) -> object:
        cfg = None if user is None else sec.config_for(user)
        s = open_session("client", connect=[ep], config_file=cfg)
        opened.append(s)
        return s

    yield sec, ep, sink, client
    for s in opened:
        s.close()
    sub.undeclare()
    router.close()


def test_files_are_private(secured) -> None:
    sec = secured[0]
    assert stat.S_IMODE(sec.directory.stat().st_mode) == 0o700
    for p in sec.directory.iterdir():
        assert stat.S_IMODE(p.stat().st_mode) == 0o600, p


def test_client_without_or_with_wrong_credentials_is_refused(secured, tmp_path: Path) -> None:
    sec, ep, _sink, _client = secured
    with pytest.raises(RuntimeError, match="cannot open zenoh client session"):
        open_session("client", connect=[ep], config_file=None, connect_timeout_ms=3000)
    other = write_swarm_security(tmp_path / "other", SWARM, [1, 2])  # same users, new pw
    with pytest.raises(RuntimeError, match="cannot open zenoh client session"):
        open_session("client", connect=[ep], config_file=other.config_for(agent_user(1)),
                     connect_timeout_ms=3000)


def test_each_process_may_publish_only_its_own_keys(secured) -> None:
    _sec, _ep, sink, client = secured
    a1, sim, gcs = client(agent_user(1)), client(SIM_USER), client(GCS_USER)
    time.sleep(0.5)
    forged = [
        (a1, wire.key_cmd(SWARM, "method")),     # an agent cannot command the swarm
        (a1, wire.key_estimate(SWARM, 2)),       # nor speak for another agent
        (a1, wire.key_status(SWARM, 2)),
        (a1, wire.key_truth(SWARM)),             # nor fake the truth
        (sim, wire.key_estimate(SWARM, 1)),
        (sim, wire.key_cmd(SWARM, "land")),
        (gcs, wire.key_truth(SWARM)),
        (a1, "swarm/other/agent/1/estimate"),   # nor reach another swarm
    ]
    for n, (sess, key) in enumerate(forged):
        sess.put(key, b"forged%d" % n)  # type: ignore[attr-defined]
    allowed = [
        (a1, wire.key_estimate(SWARM, 1)),
        (a1, wire.key_status(SWARM, 1)),
        (sim, wire.key_truth(SWARM)),
        (gcs, wire.key_cmd(SWARM, "method")),
    ]
    for sess, key in allowed:
        sess.put(key, b"ok")  # type: ignore[attr-defined]
    for _, key in allowed:
        assert sink.wait_for(key), (key, sink.keys)
    # the forged ones were put first on the same links: had they passed, they were here now
    time.sleep(0.5)
    for n, (_, key) in enumerate(forged):
        assert (key, b"forged%d" % n) not in sink.got, key


def test_a_subscriber_receives_what_was_admitted(secured) -> None:
    """Agent 2 hears agent 1's estimate and the ground station's command, through the
    router, but not a command forged by agent 1."""
    _sec, _ep, _sink, client = secured
    a1, a2, gcs = client(agent_user(1)), client(agent_user(2)), client(GCS_USER)
    heard = Sink()
    sub = a2.declare_subscriber(f"swarm/{SWARM}/**", heard)  # type: ignore[attr-defined]
    time.sleep(0.5)
    a1.put(wire.key_cmd(SWARM, "method"), b"forged")  # type: ignore[attr-defined]
    a1.put(wire.key_estimate(SWARM, 1), b"e")  # type: ignore[attr-defined]
    gcs.put(wire.key_cmd(SWARM, "land"), b"c")  # type: ignore[attr-defined]
    assert heard.wait_for(wire.key_estimate(SWARM, 1))
    assert heard.wait_for(wire.key_cmd(SWARM, "land"))
    time.sleep(0.3)
    assert wire.key_cmd(SWARM, "method") not in heard.keys
    sub.undeclare()
