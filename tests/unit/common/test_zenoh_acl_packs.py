"""The Zenoh ACL of packed daemon processes (swarm_common.zenoh_session.acl_config)."""

from __future__ import annotations

import pytest

from swarm_common.zenoh_session import acl_config, pack_user


def _puts(acl: dict, user: str) -> set[str]:
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s["usernames"] for s in acl["subjects"]}
    out: set[str] = set()
    for pol in acl["policies"]:
        if any(user in subjects[s] for s in pol["subjects"]):
            for rid in pol["rules"]:
                r = rules[rid]
                if "ingress" in r["flows"] and "put" in r["messages"]:
                    out |= set(r["key_exprs"])
    return out


def test_a_packed_process_may_put_its_own_agents_keys_only() -> None:
    acl = acl_config("s", "swarm", [1, 2, 3, 4], packs=[[1, 2], [3, 4]])
    puts = _puts(acl, pack_user([1, 2]))
    assert {"swarm/s/agent/1/estimate", "swarm/s/agent/2/odometry"} <= puts
    assert not any("/agent/3/" in k or "/agent/4/" in k or "truth" in k or "cmd" in k
                   for k in puts)
    assert acl["default_permission"] == "deny"


def test_one_agent_per_process_keeps_the_agent_users() -> None:
    assert pack_user([3]) == "agent3"
    acl = acl_config("s", "swarm", [1, 2])
    assert _puts(acl, "agent1") == {f"swarm/s/agent/1/{k}"
                                    for k in ("estimate", "status", "odometry")}


def test_packs_must_cover_every_agent_once() -> None:
    with pytest.raises(ValueError, match="exactly once"):
        acl_config("s", "swarm", [1, 2, 3], packs=[[1, 2], [2, 3]])
