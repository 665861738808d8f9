"""Open a Zenoh 1.x session the way every process of the project does (docs/conventions.md).

Defaults (docs/conventions.md, Zenoh): ``peer`` mode, explicit ``listen``/``connect`` endpoints on
127.0.0.1, multicast scouting off, gossip off, so nothing leaves the machine and nothing
is discovered by accident. ``mode="router"`` turns the session into a router (there is no
``zenohd`` binary here); ``mode="client"`` connects to a router.

    sess = open_session(listen=["tcp/127.0.0.1:7447"])                 # the simulator
    sess = open_session(connect=["tcp/127.0.0.1:7447"])                # a peer that dials it
    sess = open_session(mode="router", listen=["tcp/127.0.0.1:7447"])

A peer that only *connects* still reaches every publisher the endpoint it dials knows
about only when that endpoint is a peer that listens (or a router); with a router in the
middle, run the others as ``client`` or as peers that also listen.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import zenoh

DEFAULT_ZENOH_PORT = 7447
# A process started by a secured run finds its Zenoh config (credentials) here, by path.
ZENOH_CONFIG_ENV = "SWARM_ZENOH_CONFIG"
ZENOH_CONFIG_FLAG = "--zenoh-config"


def default_endpoint(offset: int = 0, host: str = "127.0.0.1") -> str:
    """``tcp/127.0.0.1:7447+offset``: where the simulator's session listens by default."""
    return f"tcp/{host}:{DEFAULT_ZENOH_PORT + offset}"


def make_config(
    mode: str = "peer",
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    multicast: bool = False,
    config_file: str | Path | None = None,
    connect_timeout_ms: int | None = None,
) -> zenoh.Config:
    """A ``zenoh.Config`` with the project's defaults, on top of ``config_file`` (a JSON5
    file written by :func:`write_swarm_security`: credentials, and for the router the
    access control) or, when None, the file named by ``$SWARM_ZENOH_CONFIG`` if set.
    ``connect_timeout_ms``: give up dialling after this long (default: a client waits
    forever, a peer goes on without the endpoint)."""
    import zenoh

    if config_file is None:
        config_file = os.environ.get(ZENOH_CONFIG_ENV) or None
    if mode not in ("peer", "router", "client"):
        raise ValueError(f"zenoh mode {mode!r}: must be one of 'peer', 'router', 'client'")
    for ep in [*listen, *connect]:
        if "/" not in ep:
            raise ValueError(f"zenoh endpoint {ep!r}: must look like tcp/127.0.0.1:7447")
    cfg = zenoh.Config() if config_file is None else _config_from_file(Path(config_file))
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("listen/endpoints", json.dumps(list(listen)))
    cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
    cfg.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast)))
    if not multicast:  # nothing to discover: a router or peer would wait 0.5 s in open()
        cfg.insert_json5("scouting/delay", "0")
    if mode == "peer":
        cfg.insert_json5("scouting/gossip/enabled", "false")
    # Keep retrying a connect endpoint that is not up yet (processes start in any order).
    if connect:
        if connect_timeout_ms is None:
            cfg.insert_json5("connect/timeout_ms", "-1" if mode == "client" else "0")
            cfg.insert_json5("connect/exit_on_failure", "false")
        else:
            cfg.insert_json5("connect/timeout_ms", json.dumps(int(connect_timeout_ms)))
            cfg.insert_json5("connect/exit_on_failure", "true")
    return cfg


def open_session(
    mode: str = "peer",
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    multicast: bool = False,
    config_file: str | Path | None = None,
    connect_timeout_ms: int | None = None,
) -> zenoh.Session:
    """Open and return a ``zenoh.Session``. Raises ``RuntimeError`` with one line on failure
    (for example a listen port already in use, or credentials the router refuses: the
    connect then times out)."""
    import zenoh

    cfg = make_config(mode, listen, connect, multicast, config_file, connect_timeout_ms)
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as exc:
        where = ", ".join([*listen, *connect]) or "no endpoints"
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RuntimeError(f"cannot open zenoh {mode} session ({where}): {msg}") from None


def _config_from_file(path: Path) -> zenoh.Config:
    """Load a JSON5 Zenoh config: a regular file of at most
    :data:`~swarm_common.inputs.MAX_ZENOH_CONFIG_BYTES` (never a FIFO or a device);
    ``ValueError`` (one line, never the file's content)."""
    import zenoh

    from swarm_common.inputs import MAX_ZENOH_CONFIG_BYTES, read_bounded_text

    text = read_bounded_text(path, MAX_ZENOH_CONFIG_BYTES, "zenoh config")  # ValueError
    try:
        return zenoh.Config.from_json5(text)
    except (zenoh.ZError, OSError) as exc:
        why = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else "unreadable"
        raise ValueError(f"zenoh config {path}: cannot load ({why})") from None


# --------------------------------------------------------------------------------------
# Authentication (user/password) and access control of one swarm (docs/security.md).
# --------------------------------------------------------------------------------------
GCS_USER = "gcs"  # the runner / ``gcs router`` (router session) and the ground station
SIM_USER = "sim"
_SUB_MESSAGES = [
    "declare_subscriber", "declare_liveliness_subscriber", "liveliness_token",
    "liveliness_query", "query", "declare_queryable", "reply",
]  # fmt: skip
_PUT = ["put", "delete"]
# what agent i may put, each under <root>/<swarm>/agent/i/ (swarm_common.wire's key_*)
AGENT_KEYS = ("estimate", "status", "odometry")


def agent_user(agent_id: int) -> str:
    return f"agent{agent_id}"


def pack_user(agent_ids: Sequence[int]) -> str:
    """The Zenoh user of one daemon process: ``agent<i>`` for one agent, ``agents<i>_<j>_..``
    for several packed in one process (``offboard --agents``)."""
    ids = list(agent_ids)
    if len(ids) == 1:
        return agent_user(ids[0])
    return "agents" + "_".join(str(i) for i in ids)


def _packs(agent_ids: Iterable[int], packs: Sequence[Sequence[int]] | None) -> list[list[int]]:
    """``packs`` (validated: every agent exactly once) or one pack per agent."""
    ids = list(agent_ids)
    if packs is None:
        return [[i] for i in ids]
    out = [list(p) for p in packs]
    flat = [i for p in out for i in p]
    if sorted(flat) != sorted(ids) or any(not p for p in out):
        raise ValueError(f"packs {out} must hold every agent of {ids} exactly once")
    return out


@dataclass(frozen=True)
class SwarmSecurity:
    """Where one swarm's generated Zenoh security files are: ``router`` (router config:
    dictionary of every user + ACL), and one client config per process (``config_for``)."""

    directory: Path
    router: Path

    def config_for(self, user: str) -> Path:
        return self.directory / f"{user}.json5"


def acl_config(
    swarm: str, root: str, agent_ids: Iterable[int],
    packs: Sequence[Sequence[int]] | None = None,
) -> dict[str, Any]:
    """The router's ``access_control`` section: default deny; every authenticated user may
    subscribe under ``<root>/<swarm>/**``; only ``sim`` may put ``truth``; agent ``i`` only
    its own ``agent/i/estimate``, ``agent/i/status`` and ``agent/i/odometry`` (the keys
    of :data:`AGENT_KEYS`); only ``gcs`` may put ``cmd/**``. With ``packs`` (agents packed
    into one daemon process), the process's user (:func:`pack_user`) may put the keys of
    its own agents only. Messages the router forwards (egress) are allowed, so a
    subscriber receives what was admitted."""
    base = f"{root}/{swarm}"
    groups = _packs(agent_ids, packs)
    users = [GCS_USER, SIM_USER, *(pack_user(g) for g in groups)]
    rules: list[dict[str, Any]] = [
        {"id": "subscribe", "permission": "allow", "flows": ["ingress", "egress"],
         "messages": _SUB_MESSAGES, "key_exprs": [f"{base}/**"]},
        {"id": "forward", "permission": "allow", "flows": ["egress"], "messages": _PUT,
         "key_exprs": [f"{base}/**"]},
        {"id": "put_truth", "permission": "allow", "flows": ["ingress"], "messages": _PUT,
         "key_exprs": [f"{base}/truth"]},
        {"id": "put_cmd", "permission": "allow", "flows": ["ingress"], "messages": _PUT,
         "key_exprs": [f"{base}/cmd/**"]},
    ]  # fmt: skip
    subjects: list[dict[str, Any]] = [
        {"id": "everyone", "usernames": users},
        {"id": SIM_USER, "usernames": [SIM_USER]},
        {"id": GCS_USER, "usernames": [GCS_USER]},
    ]
    policies: list[dict[str, Any]] = [
        {"rules": ["subscribe", "forward"], "subjects": ["everyone"]},
        {"rules": ["put_truth"], "subjects": [SIM_USER]},
        {"rules": ["put_cmd"], "subjects": [GCS_USER]},
    ]
    for g in groups:
        u = pack_user(g)
        rules.append({"id": f"put_{u}", "permission": "allow", "flows": ["ingress"],
                      "messages": _PUT,
                      "key_exprs": [f"{base}/agent/{i}/{key}" for i in g for key in AGENT_KEYS]})
        subjects.append({"id": u, "usernames": [u]})
        policies.append({"rules": [f"put_{u}"], "subjects": [u]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def _write_private(path: Path, text: str) -> None:
    """Create ``path`` with mode 0600 (never readable by others, even for a moment)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.chmod(path, 0o600)


def write_swarm_security(
    directory: Path, swarm: str, agent_ids: Iterable[int], root: str = "swarm",
    packs: Sequence[Sequence[int]] | None = None,
) -> SwarmSecurity:
    """Generate fresh random passwords for ``gcs``, ``sim`` and ``agent<i>`` (or, with
    ``packs``, one user per daemon process: :func:`pack_user`) and write, in
    ``directory`` (created 0700): ``users`` (the router's dictionary, ``user:password``
    lines), ``router.json5`` (router: its credentials, the dictionary, :func:`acl_config`)
    and ``<user>.json5`` per process (its own credentials only). Every file is 0600.
    Passwords are never logged; processes get the path of their file."""
    ids = list(agent_ids)
    groups = _packs(ids, packs)
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(directory, 0o700)
    users = [GCS_USER, SIM_USER, *(pack_user(g) for g in groups)]
    pw = {u: secrets.token_urlsafe(24) for u in users}
    dictionary = directory / "users"
    _write_private(dictionary, "".join(f"{u}:{pw[u]}\n" for u in users))
    sec = SwarmSecurity(directory, directory / "router.json5")
    router_cfg = {
        "transport": {"auth": {"usrpwd": {"user": GCS_USER, "password": pw[GCS_USER],
                                          "dictionary_file": str(dictionary)}}},
        "access_control": acl_config(swarm, root, ids, groups),
    }
    _write_private(sec.router, json.dumps(router_cfg, indent=1))
    for u in users:
        # A process that also listens (the simulator's peer endpoint) accepts only its own
        # credentials there: nobody is meant to dial it, the router is the only hub.
        own = directory / f".{u}.users"
        _write_private(own, f"{u}:{pw[u]}\n")
        cfg = {"transport": {"auth": {"usrpwd": {"user": u, "password": pw[u],
                                                 "dictionary_file": str(own)}}}}
        _write_private(sec.config_for(u), json.dumps(cfg, indent=1))
    return sec
