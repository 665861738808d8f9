"""Packed daemons: the --agents text, the process split, peers and the decode cache."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.mission.launch_spec import LaunchError, LaunchSpec
from offboard.agent.peers import peer_ids, ready_ids
from offboard.daemon.packing import brief_ids, brief_text, format_agents, parse_agents
from offboard.daemon.zenoh.link import DecodeCache
from offboard.estimation.bearing import formation_from_scenario
from swarm_common import wire
from swarm_common.scenario.model import load_scenario

SCEN = Path(__file__).resolve().parents[3] / "scenarios"


def test_parse_and_format_agents() -> None:
    assert parse_agents("3-8") == [3, 4, 5, 6, 7, 8]
    assert parse_agents("1,2,5") == [1, 2, 5]
    assert parse_agents("1-3,2,7") == [1, 2, 3, 7]
    assert format_agents([3, 4, 5]) == "3-5"
    assert format_agents([1, 2, 5]) == "1,2,5"
    assert format_agents([4]) == "4"
    for bad in ("", "x", "5-3", "0", "1-", "-2"):
        with pytest.raises(ValueError):
            parse_agents(bad)


def test_launch_spec_packs_contiguous_and_balanced() -> None:
    sc = load_scenario(str(SCEN / "cube8.toml"))
    assert LaunchSpec(sc).packs() == [[i] for i in sc.ids]
    spec = LaunchSpec(sc, daemon_processes=3)
    assert spec.packs() == [[1, 2, 3], [4, 5, 6], [7, 8]]
    names = [name for name, _ in spec.processes()]
    assert names == ["vehicle-sim", "offboard-1-3", "offboard-4-6", "offboard-7-8"]
    argv = spec.daemon_argv([4, 5, 6])
    assert argv[argv.index("--agents") + 1] == "4-6" and "--agent" not in argv
    with pytest.raises(LaunchError, match="--processes 9"):
        LaunchSpec(sc, daemon_processes=9)


def test_peers_all_on_cube8_few_on_a_sparse_grid_none_for_leaders() -> None:
    sc = load_scenario(str(SCEN / "cube8.toml"))
    form = formation_from_scenario(sc)
    assert all(ready_ids(form, i) == [j for j in sc.ids if j != i] for i in sc.ids)
    followers = [i for i in sc.ids if i not in sc.leader_ids]
    assert all(peer_ids(form, i) == ready_ids(form, i) for i in followers)
    sc = load_scenario(str(SCEN / "grid27_knn.toml"))
    form = formation_from_scenario(sc)
    dropped = 0
    for i in sc.ids:
        ready, x = ready_ids(form, i), form.index_of(i)
        assert i not in ready and set(sc.leader_ids) - {i} <= set(ready)
        nb = {form.ids[j] for j in form.neighbours[x]}
        assert nb <= set(ready)
        if i in sc.leader_ids:
            assert peer_ids(form, i) == []
            continue
        # a follower's peers: its neighbours and the agents nearest its vertex, so a
        # leader farther than every other peer is awaited before the first step only
        peers = set(peer_ids(form, i))
        assert nb <= peers <= set(ready)
        far = set(ready) - peers
        assert far <= set(sc.leader_ids)
        d = np.linalg.norm(form.vertices - form.vertices[x], axis=1)
        near = [d[form.index_of(j)] for j in peers - nb]
        if far and near:
            assert max(near) < min(d[form.index_of(j)] for j in far)
        dropped += len(far)
    assert dropped > 0
    assert min(len(ready_ids(form, i)) for i in sc.ids) < len(sc.ids) - 1


def test_decode_cache_returns_the_decoded_payload_and_rejects_garbage() -> None:
    cache = DecodeCache(entries=2)
    cmd = wire.Command("method", 0, method="apf")
    data = wire.encode(cmd)
    first = cache.decode(data)
    assert isinstance(first, wire.Command) and first.method == "apf"
    assert cache.decode(data) is first
    with pytest.raises(wire.WireError):
        cache.decode(b"\x00garbage")


def test_decode_cache_judges_finiteness_once_per_payload() -> None:
    from offboard.daemon.link_guard import PayloadGuard

    cache = DecodeCache()
    good = wire.Estimate(id=3, step=-1, t=0.0, role="follower", z1=np.ones(3),
                         z2=np.zeros(3), z3=np.zeros(3), xi=np.zeros(12), zeta=np.zeros(6))
    bad = wire.Estimate(id=3, step=-1, t=0.0, role="follower",
                        z1=np.array([0.0, np.nan, 0.0]), z2=np.zeros(3), z3=np.zeros(3),
                        xi=np.zeros(12), zeta=np.zeros(6))
    msg, finite = cache.decode_checked(wire.encode(good))
    assert finite and cache.decode_checked(wire.encode(good))[0] is msg
    bad_msg, bad_finite = cache.decode_checked(wire.encode(bad))
    assert not bad_finite
    # two packed daemons' guards on the one decoded payload: same verdicts
    for own in (3, 4):
        g = PayloadGuard([1, 2, 3, 4], [1, 2], 50.0, own_id=own)
        assert g.check(msg, finite) is None
        assert g.check(bad_msg, bad_finite) == "estimate has non-finite values"
        assert g.check(bad_msg) == "estimate has non-finite values"  # computed when absent


def test_brief_ids_and_text_keep_an_error_line_short():
    """``--agents 1-300`` on an 8-agent scenario: 292 unknown ids, shown as the first few
    and the count (the whole list was a 1.4 kB line); a long --agents text is cut."""
    assert brief_ids([9]) == "[9]"
    shown = brief_ids(list(range(9, 301)))
    assert shown == "[9, 10, 11, 12, 13, 14, 15, 16, ... (292 ids)]"
    assert brief_text("1-300") == "'1-300'"
    assert len(brief_text("1," * 5000)) < 50
    with pytest.raises(ValueError) as ei:
        parse_agents("9" * 5000)
    assert len(str(ei.value)) < 100
