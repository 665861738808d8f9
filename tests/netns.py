"""A small LAN of Linux network namespaces for multi-host tests (needs root and iproute2).

:func:`netns_lan` creates ``n`` host namespaces and one switch namespace holding a bridge;
each host gets ``eth0`` (a veth to the bridge) with a private address on one /24 and
``lo`` up. Names carry the pid and a counter (``swt<pid>x<k>h<i>``), so two copies of the
suite side by side never clash; the /24 is chosen from the pid too (inside namespaces
addresses cannot clash anyway, but a leak is then easy to attribute). Everything is
deleted on the way out, even when the body raises; namespaces left by a run killed with
-9 are deleted by the next run once their pid is gone. Literal IPv4 addresses only.

:func:`netns_unavailable` says why namespaces cannot be made here (not root, no ``ip``,
the kernel refuses), for a skip message.
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import subprocess
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

_counter = itertools.count()


def _ip(*args: str) -> None:
    """Run ``ip ARGS``; raise RuntimeError with ip's own one-line complaint on failure."""
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if out.returncode != 0:
        why = (out.stderr.strip().splitlines() or ["failed"])[-1]
        raise RuntimeError(f"ip {' '.join(args)}: {why}")


def netns_unavailable() -> str | None:
    """None when this process can create network namespaces, else the reason."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "network namespaces need iproute2 (no 'ip' on PATH)"
    probe = f"swt{os.getpid()}probe"
    try:
        _ip("netns", "add", probe)
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
        return f"cannot create a network namespace: {exc}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True, timeout=30)
    return None


@dataclass(frozen=True)
class Lan:
    """Host namespaces ``hosts[i]`` with address ``ips[i]`` on one /24 behind a bridge."""

    hosts: list[str]
    ips: list[str]
    switch: str

    def exec_argv(self, host: int, argv: Sequence[str]) -> list[str]:
        """``argv`` run inside host ``host``'s namespace (``ip netns exec`` execs it, so
        the pid of the Popen is the program's own)."""
        return ["ip", "netns", "exec", self.hosts[host], *argv]

    def keep_udp_local(self, host: int, peer_ip: str, ports: range) -> None:
        """In host ``host``, UDP between this host and ``peer_ip`` on local ports ``ports``
        stays on this host, both ways: datagrams sent to ``peer_ip`` on those ports are
        delivered to this host's own sockets, and datagrams sent *from* those ports to this
        host's address carry ``peer_ip`` as their source. A process that sends every
        stream to one remote address (the simulator's ``--remote-host``) then serves
        receivers on two hosts, and cannot tell the local ones from the remote ones.
        Policy rules (table 100) ahead of the ``local`` table; nothing else changes."""
        ns, own = self.hosts[host], self.ips[host]
        dports = f"{ports.start}-{ports.stop - 1}"
        _ip("-n", ns, "route", "add", "local", peer_ip, "dev", "lo", "table", "100")
        _ip("-n", ns, "route", "add", "local", own, "dev", "lo", "src", peer_ip,
            "table", "100")  # fmt: skip
        _ip("-n", ns, "rule", "add", "pref", "10", "to", peer_ip, "ipproto", "udp",
            "dport", dports, "lookup", "100")  # fmt: skip
        _ip("-n", ns, "rule", "add", "pref", "11", "to", own, "ipproto", "udp",
            "sport", dports, "lookup", "100")  # fmt: skip
        _ip("-n", ns, "rule", "add", "pref", "100", "lookup", "local")
        _ip("-n", ns, "rule", "del", "pref", "0")


def _reap_stale() -> None:
    """Delete the namespaces of earlier runs whose process is gone (a test killed with -9
    cannot clean up; its namespaces are named after its pid)."""
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=30)
    for line in out.stdout.splitlines():
        m = re.match(r"(swt(\d+)x\d+(?:sw|h\d+))\b", line)
        if m and int(m.group(2)) != os.getpid() and not os.path.exists(f"/proc/{m.group(2)}"):
            subprocess.run(["ip", "netns", "del", m.group(1)], capture_output=True, timeout=30)


def _subnet() -> str:
    """``10.a.b`` from the pid: a /24 that differs between processes."""
    pid = os.getpid()
    return f"10.{100 + pid % 100}.{(pid // 100) % 250}"


@contextmanager
def netns_lan(n: int) -> Iterator[Lan]:
    """Create ``n`` host namespaces on one bridged /24 (hosts .1 .. .n); delete them all
    when the block ends, whatever happens. Processes started in them must be stopped
    first (a namespace lives on while a process is in it)."""
    tag = f"swt{os.getpid()}x{next(_counter)}"
    switch, hosts = f"{tag}sw", [f"{tag}h{i}" for i in range(n)]
    net = _subnet()
    ips = [f"{net}.{i + 1}" for i in range(n)]
    made: list[str] = []
    _reap_stale()
    try:
        for ns in (switch, *hosts):
            _ip("netns", "add", ns)
            made.append(ns)
        _ip("-n", switch, "link", "add", "br0", "type", "bridge", "forward_delay", "0")
        _ip("-n", switch, "link", "set", "br0", "up")
        for i, (ns, ip) in enumerate(zip(hosts, ips, strict=True)):
            port = f"p{i}"
            _ip("-n", ns, "link", "add", "eth0", "type", "veth", "peer", "name", port,
                "netns", switch)  # fmt: skip
            _ip("-n", switch, "link", "set", port, "master", "br0")
            _ip("-n", switch, "link", "set", port, "up")
            _ip("-n", ns, "addr", "add", f"{ip}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", ns, "link", "set", "lo", "up")
        yield Lan(hosts, ips, switch)
    finally:
        for ns in reversed(made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
