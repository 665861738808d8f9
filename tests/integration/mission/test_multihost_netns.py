"""Multi-host swarm in Linux network namespaces, Zenoh authentication and ACL on.

Three "hosts" on one bridged /24 (tests/netns.py), every address a literal IPv4:

* host A: ``gcs router --listen tcp/<A>:7447 --scenario cube8 --secure-dir DIR``, which
  generates the credentials and the ACL;
* host B: ``vehicle-sim`` (all 8 vehicles, MAVLink bound on B, default streams sent to C)
  and the daemons of agents 1-4; a policy rule in B keeps the streams of vehicles 1-4 on
  B (:meth:`netns.Lan.keep_udp_local`);
* host C: the daemons of agents 5-8, an authenticated observer (the ``gcs`` credentials),
  a forger without credentials, and connection probes.

Every swarm process dials the router with its own ``<user>.json5``; MAVLink crosses from
B to C over UDP, signed with one key. The lockstep run advances only when every daemon
answers, so a completed run shows both transports crossing the hosts.
"""

from __future__ import annotations

import ctypes
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import CUBE8, ROOT
from netns import Lan, netns_lan, netns_unavailable

from swarm_common.ports import vehicle_ports
from swarm_common.scenario.model import load_scenario
from swarm_common.signing import generate_key
from swarm_common.zenoh_session import (
    DEFAULT_ZENOH_PORT,
    GCS_USER,
    SIM_USER,
    ZENOH_CONFIG_ENV,
    agent_user,
    write_swarm_security,
)

pytestmark = pytest.mark.timeout(240)
A, B, C = 0, 1, 2
ON_B = (1, 2, 3, 4)  # the daemons on host B; the others run on host C
DURATION_S = 4.0  # simulated; the followers' mean error falls by more than half (0.8 -> 0.2 m)
PR_SET_PDEATHSIG = 1  # linux/prctl.h

# Runs in host C with the gcs credentials: records what the router delivers.
OBSERVER = r"""
import json, sys, threading, time
import numpy as np
from swarm_common import wire
from swarm_common.scenario.model import load_scenario
from swarm_common.zenoh_session import open_session
ep, cfg, scen, last, timeout, out = sys.argv[1:7]
sc = load_scenario(scen)
fol = [sc.index_of(i) for i in sc.follower_ids]
lock = threading.Lock()
truth, pdes, est, methods, cmds = {}, {}, set(), set(), []
def on(sample):
    key = str(sample.key_expr)
    try:
        obj = wire.decode(sample.payload.to_bytes())
    except wire.WireError:
        return
    with lock:
        if isinstance(obj, wire.Truth):
            truth[obj.step] = obj
        elif isinstance(obj, wire.Estimate):
            est.add(obj.id)
        elif isinstance(obj, wire.Status):
            methods.add(obj.method)
            pdes[(obj.step, obj.id)] = np.asarray(obj.p_des, float)
        elif isinstance(obj, wire.Command):
            cmds.append(key)
s = open_session("client", connect=[ep], config_file=cfg)
sub = s.declare_subscriber(f"swarm/{sc.name}/**", on)
print("READY", flush=True)
deadline = time.monotonic() + float(timeout)
while time.monotonic() < deadline:
    with lock:
        if truth and max(truth) >= int(last):
            break
    time.sleep(0.1)
time.sleep(0.5)
with lock:
    def err(k):
        ids = sc.follower_ids
        if k not in truth or any((k, i) not in pdes for i in ids):
            return None
        p = truth[k].p
        return float(np.mean([np.linalg.norm(p[j] - pdes[(k, i)]) for j, i in zip(fol, ids)]))
    errs = [e for k in sorted(truth) if (e := err(k)) is not None]
    last_t = truth[max(truth)] if truth else None
    doc = {
        "max_step": max(truth) if truth else -1,
        "estimates_from": sorted(est), "methods": sorted(methods), "commands": cmds,
        "err_first": errs[0] if errs else None, "err_last": errs[-1] if errs else None,
        "collisions": max((t.collisions for t in truth.values()), default=-1),
        "min_dist": min((t.min_dist for t in truth.values()), default=-1.0),
        "modes": list(last_t.mode) if last_t else [],
    }
open(out, "w").write(json.dumps(doc))
sub.undeclare()
s.close()
"""

# Runs in host C: can a client session be opened with this config ("" = none)?
PROBE = r"""
import sys
from swarm_common.zenoh_session import open_session
cfg = sys.argv[2] or None
try:
    s = open_session("client", connect=[sys.argv[1]], config_file=cfg, connect_timeout_ms=3000)
except RuntimeError as exc:
    print("REFUSED", exc)
else:
    s.close()
    print("OPENED")
"""

# Runs in host C without credentials: a peer session (it opens without the router) that
# keeps publishing the "switch avoidance off" command of the unauthenticated attack.
FORGER = r"""
import sys, time
from swarm_common import wire
from swarm_common.zenoh_session import open_session
s = open_session("peer", connect=[sys.argv[1]])
key = wire.key_cmd(sys.argv[2], "method")
print("FORGING", flush=True)
while True:
    s.put(key, wire.encode(wire.Command(kind="method", method="none")))
    time.sleep(0.05)
"""


def _die_with_us() -> None:
    """``preexec_fn``: SIGKILL the child if the test process dies (even by kill -9), so no
    router or daemon outlives a killed test run; kept across ``ip netns exec``'s exec."""
    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)


def _env() -> dict[str, str]:
    """The children's environment: never a credentials file by inheritance."""
    env = {k: v for k, v in os.environ.items() if k != ZENOH_CONFIG_ENV}
    env["PYTHONUNBUFFERED"] = "1"
    return env


class Hosts:
    """Processes started in the namespaces of a :class:`~netns.Lan`, logs in ``logs``."""

    def __init__(self, lan: Lan, logs: Path) -> None:
        self.lan, self.logs = lan, logs
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        logs.mkdir(parents=True, exist_ok=True)

    def start(self, name: str, host: int, argv: list[str]) -> subprocess.Popen[bytes]:
        with (self.logs / f"{name}.log").open("wb") as log:
            p = subprocess.Popen(self.lan.exec_argv(host, argv), cwd=ROOT, env=_env(),
                                 stdout=log, stderr=subprocess.STDOUT,
                                 preexec_fn=_die_with_us)
        self.procs[name] = p
        return p

    def python(self, name: str, host: int, code: str, *args: str) -> subprocess.Popen[bytes]:
        return self.start(name, host, [sys.executable, "-c", code, *args])

    def log(self, name: str) -> str:
        return (self.logs / f"{name}.log").read_text(errors="replace")

    def wait_log(self, name: str, text: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.log(name):
                return
            if self.procs[name].poll() is not None:
                break
            time.sleep(0.1)
        raise AssertionError(f"{name}: no {text!r} in its log:\n{self.tails([name])}")

    def tails(self, names: list[str] | None = None, lines: int = 8) -> str:
        out = []
        for n in names or list(self.procs):
            tail = self.log(n).strip().splitlines()[-lines:]
            out.append(f"--- {n} (rc {self.procs[n].poll()}):\n" + "\n".join(tail))
        return "\n".join(out)

    def stop(self, names: list[str] | None = None) -> None:
        """SIGTERM, then SIGKILL after 5 s; every process is reaped."""
        chosen = [self.procs[n] for n in (names or list(self.procs))]
        for p in chosen:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 5.0
        for p in chosen:
            try:
                p.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5)


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Hosts, Path, str]]:
    """The LAN and the router on host A; yields (hosts, secure dir, router endpoint)."""
    why = netns_unavailable()
    if why is not None:
        pytest.skip(why)
    base = tmp_path_factory.mktemp("multihost")
    secure = base / "secure"
    with netns_lan(3) as lan:
        hosts = Hosts(lan, base / "logs")
        ep = f"tcp/{lan.ips[A]}:{DEFAULT_ZENOH_PORT}"
        try:
            hosts.start("router", A, [sys.executable, "-m", "gcs.cli", "--log-level", "info",
                                      "router", "--listen", ep, "--scenario", CUBE8,
                                      "--secure-dir", str(secure)])
            hosts.wait_log("router", "listening on", 60)
            yield hosts, secure, ep
        finally:
            hosts.stop()


def _probe(hosts: Hosts, name: str, ep: str, cfg: Path | None) -> str:
    p = hosts.python(name, C, PROBE, ep, "" if cfg is None else str(cfg))
    p.wait(60)
    return hosts.log(name)


def test_router_generates_private_credentials(net: tuple[Hosts, Path, str]) -> None:
    _hosts, secure, _ep = net
    users = {GCS_USER, SIM_USER, *(agent_user(i) for i in load_scenario(CUBE8).ids)}
    assert {f"{u}.json5" for u in users} | {"router.json5"} <= {p.name for p in
                                                                secure.iterdir()}
    assert secure.stat().st_mode & 0o077 == 0
    assert all(p.stat().st_mode & 0o077 == 0 for p in secure.iterdir())


def test_client_on_another_host_needs_the_right_credentials(
    net: tuple[Hosts, Path, str], tmp_path: Path
) -> None:
    hosts, secure, ep = net
    # the network path works: with its own credentials, host C's client is admitted
    assert "OPENED" in _probe(hosts, "probe-good", ep, secure / "agent5.json5")
    # no credentials: Zenoh refuses the session (the connect times out, open fails)
    out = _probe(hosts, "probe-none", ep, None)
    assert "REFUSED" in out and "cannot open zenoh client session" in out, out
    # the same user name with another password
    other = write_swarm_security(tmp_path / "other", "cube8", [5])
    out = _probe(hosts, "probe-wrong", ep, other.config_for(agent_user(5)))
    assert "REFUSED" in out and "cannot open zenoh client session" in out, out


def test_swarm_flies_across_hosts_and_an_unauthenticated_peer_is_ignored(
    net: tuple[Hosts, Path, str], tmp_path: Path
) -> None:
    hosts, secure, ep = net
    lan, sc = hosts.lan, load_scenario(CUBE8)
    key = tmp_path / "mavlink.key"
    generate_key(key)
    lan.keep_udp_local(B, lan.ips[C], range(vehicle_ports(ON_B[0], 0).api_remote,
                                                 vehicle_ports(ON_B[-1], 0).api_remote + 1))
    last_step = int(round(DURATION_S * sc.run.control_hz)) - 1
    result = tmp_path / "observed.json"
    names = ["observer", "forger", "vehicle-sim", *(f"offboard-{i}" for i in sc.ids)]
    try:
        hosts.python("observer", C, OBSERVER, ep, str(secure / f"{GCS_USER}.json5"), CUBE8,
                     str(last_step), "150", str(result))
        hosts.wait_log("observer", "READY", 60)
        hosts.python("forger", C, FORGER, ep, sc.name)
        hosts.wait_log("forger", "FORGING", 60)
        hosts.start("vehicle-sim", B, [
            sys.executable, "-m", "vehicle_sim.cli", "--scenario", CUBE8, "--lockstep",
            "--step-timeout", "1.0", "--duration", f"{DURATION_S + 0.5}",
            "--bind", lan.ips[B], "--remote-host", lan.ips[C],
            "--zenoh-mode", "client", "--zenoh-connect", ep,
            "--zenoh-config", str(secure / f"{SIM_USER}.json5"),
            "--signing-key", str(key), "--stats-out", str(tmp_path / "sim-stats.json"),
        ])  # fmt: skip
        for i in sc.ids:
            port = vehicle_ports(i, 0).api_remote
            host, bind = (B, "0.0.0.0") if i in ON_B else (C, lan.ips[C])
            hosts.start(f"offboard-{i}", host, [
                sys.executable, "-m", "offboard.cli", "--scenario", CUBE8, "--agent", str(i),
                "--mavlink", f"udpin:{bind}:{port}", "--zenoh-connect", ep,
                "--zenoh-config", str(secure / f"{agent_user(i)}.json5"),
                "--signing-key", str(key),
            ])  # fmt: skip
        hosts.procs["observer"].wait(200)
        hosts.procs["vehicle-sim"].wait(30)  # it exits by itself after --duration
    finally:
        forger_alive = hosts.procs["forger"].poll() is None
        tails = hosts.tails(names)
        hosts.stop(names)
    assert result.exists(), tails
    doc: dict[str, Any] = json.loads(result.read_text())
    # the lockstep run reached its last step: every daemon, on B and on C, answered each step
    assert doc["max_step"] >= last_step, (doc, tails)
    assert doc["estimates_from"] == sorted(sc.ids), doc  # estimates crossed the router
    assert doc["modes"] == ["OFFBOARD"] * sc.n, doc
    assert doc["collisions"] == 0 and doc["min_dist"] >= 0.5, doc
    assert doc["err_first"] is not None and doc["err_last"] < 0.5 * doc["err_first"], doc
    # the forger kept publishing "avoidance off" all along, and it never reached anyone:
    # no command was delivered and every agent kept the scenario's method
    assert forger_alive, tails
    assert doc["commands"] == [], doc
    assert doc["methods"] == [str(sc.controller.method)], doc
    # our own MAVLink frames were never rejected, on either side of the link
    links = json.loads((tmp_path / "sim-stats.json").read_text())["links"]
    assert {k: v for k, v in links.items() if k.startswith("rejected") and v} == {}, links
    for i in sc.ids:
        assert "bad signature" not in hosts.log(f"offboard-{i}"), hosts.tails([f"offboard-{i}"])
