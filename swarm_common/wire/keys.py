"""Zenoh key expressions of one swarm (the table in :mod:`swarm_common.wire`)."""

from __future__ import annotations

from swarm_common.wire.payloads import WireError

DEFAULT_ROOT = "swarm"


# -- key expressions -----------------------------------------------------------------
def key_truth(swarm: str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/truth"


def key_estimate(swarm: str, agent_id: int | str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/agent/{agent_id}/estimate"


def key_status(swarm: str, agent_id: int | str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/agent/{agent_id}/status"


def key_odometry(swarm: str, agent_id: int | str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/agent/{agent_id}/odometry"


def key_cmd(swarm: str, kind: str, root: str = DEFAULT_ROOT) -> str:
    return f"{root}/{swarm}/cmd/{kind}"


def agent_id_from_key(key: str) -> int:
    """``.../agent/<id>/...`` -> id."""
    parts = str(key).split("/")
    try:
        return int(parts[parts.index("agent") + 1])
    except (ValueError, IndexError) as exc:
        raise WireError(f"no agent id in key {key!r}") from exc

