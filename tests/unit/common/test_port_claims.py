"""Port-offset claims between test sessions (tests/conftest.py): a second copy of the suite
on the same machine never gets an offset this session holds, and a claim left by a dead
session is taken over."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import conftest
import pytest

from swarm_common.ports import swarm_udp_ports
from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT


def test_claims_block_live_owners_and_take_over_dead_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(conftest, "CLAIM_DIR", tmp_path)
    monkeypatch.setattr(conftest, "_claimed", [])
    assert conftest._claim_offset(7000)
    assert (tmp_path / "7000.pid").read_text() == str(os.getpid())
    # held by another live process (pid 1 always exists)
    (tmp_path / "8000.pid").write_text("1")
    assert not conftest._claim_offset(8000)
    # held by a process that has exited: a stale claim, taken over
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / "9000.pid").write_text(str(dead.pid))
    assert conftest._claim_offset(9000)
    assert (tmp_path / "9000.pid").read_text() == str(os.getpid())
    conftest.release_port_offsets()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["8000.pid"]  # not ours to free


def test_a_session_that_used_every_offset_reuses_the_oldest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Offsets not used yet in the session come first; once the pool is used up, the one
    used longest ago whose ports are free is given again, not a RuntimeError."""
    monkeypatch.setattr(conftest, "CLAIM_DIR", tmp_path)
    monkeypatch.setattr(conftest, "_claimed", [])
    pool = conftest.OFFSET_POOL[:3]
    monkeypatch.setattr(conftest, "OFFSET_POOL", pool)
    monkeypatch.setattr(conftest, "_used_offsets", [])
    monkeypatch.setattr(conftest, "port_free", lambda port, kind=None, allow_time_wait=False: True)
    got = []
    for _ in range(3):
        got.append(conftest.free_port_offset())
        conftest.release_port_offsets()
    assert sorted(got) == sorted(pool)  # each fresh one once
    assert conftest.free_port_offset() == got[0]  # then the oldest
    conftest.release_port_offsets()
    # an offset another live session holds is skipped even when it is the oldest
    (tmp_path / f"{got[1]}.pid").write_text("1")
    assert conftest.free_port_offset() == got[2]
    conftest.release_port_offsets()


def test_the_pool_keeps_every_port_out_of_the_ephemeral_range(tmp_path: Path) -> None:
    """With Linux's default range every offset's ports (Zenoh's router and simulator,
    every vehicle port up to id 255) lie below it; an unreadable range file falls back to
    that default; a range that leaves too few offsets outside gives every candidate."""
    lo, hi = 32768, 60999
    pool = conftest.offset_pool((lo, hi))
    assert len(pool) >= 12 and 0 not in pool
    for off in pool:
        ports = [*swarm_udp_ports(list(range(1, 256)), off),
                 DEFAULT_ZENOH_PORT + off, DEFAULT_ZENOH_PORT + off + 1]
        assert all(p < lo or p > hi for p in ports), off
    assert conftest.ephemeral_port_range(tmp_path / "missing") == (lo, hi)
    (tmp_path / "range").write_text("40000\t50000\n")
    assert conftest.ephemeral_port_range(tmp_path / "range") == (40000, 50000)
    assert len(conftest.offset_pool((1024, 65535))) == 90  # nothing outside: every one


def test_a_claim_covers_the_offsets_its_swarm_reaches(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From 11 vehicles on, a swarm at offset 1300 uses vehicle 1's API port of offset 5300
    (19880): a claim of 1300 holds 5300 too, and 1300 is not given while another session
    flies at 5300."""
    assert 19880 in swarm_udp_ports(list(range(1, 12)), 1300)
    assert 19880 in swarm_udp_ports([1], 5300)
    assert conftest.reached_offsets(1300, 8) == []
    monkeypatch.setattr(conftest, "CLAIM_DIR", tmp_path)
    monkeypatch.setattr(conftest, "_claimed", [])
    monkeypatch.setattr(conftest, "OFFSET_POOL", (1300, 5300, 7000))
    monkeypatch.setattr(conftest, "port_free", lambda port, kind=None, allow_time_wait=False: True)
    assert conftest.reached_offsets(1300, 27) == [5300]
    monkeypatch.setattr(conftest, "_used_offsets", [5300, 7000])  # 1300 comes first
    assert conftest.free_port_offset() == 1300
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1300.pid", "5300.pid"]
    conftest.release_port_offsets()
    assert list(tmp_path.iterdir()) == []
    # another live session flies at 5300: 1300 would meet it, 5300 is held, 7000 is given
    (tmp_path / "5300.pid").write_text("1")
    monkeypatch.setattr(conftest, "_used_offsets", [5300, 7000])
    assert conftest.free_port_offset() == 7000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["5300.pid", "7000.pid"]
    conftest.release_port_offsets()
