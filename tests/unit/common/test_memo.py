"""swarm_common.memo: once per (object, parameters) by identity, or per key by
content; bounded."""

from __future__ import annotations

from collections.abc import Callable

from swarm_common.memo import ContentMemo, IdentityMemo


def _recorded() -> tuple[list[int], Callable[[int], int]]:
    """(calls, compute): compute(v) returns v and records that it ran."""
    calls: list[int] = []

    def compute(v: int) -> int:
        calls.append(v)
        return v

    return calls, compute


def test_computed_once_per_object_and_parameters() -> None:
    memo: IdentityMemo[int] = IdentityMemo(size=2)
    calls, compute = _recorded()
    a, b = [1], [1]  # equal, but two objects
    assert memo.get(a, "p", lambda: compute(10)) == 10
    assert memo.get(a, "p", lambda: compute(11)) == 10  # cached
    assert memo.get(a, "q", lambda: compute(12)) == 12  # other parameters
    assert memo.get(b, "p", lambda: compute(13)) == 13  # other object, though equal
    assert calls == [10, 12, 13]
    # size 2: the oldest entry (a, "p") was dropped for (b, "p")
    assert memo.get(a, "p", lambda: compute(14)) == 14


def test_content_memo_shares_equal_keys_and_is_bounded() -> None:
    memo: ContentMemo[int] = ContentMemo(size=2)
    calls, compute = _recorded()
    assert memo.get(("d1", 1), lambda: compute(10)) == 10
    assert memo.get(("d1", 1), lambda: compute(11)) == 10  # an equal key: shared
    assert memo.get(("d1", 2), lambda: compute(12)) == 12
    assert memo.get(("d2", 1), lambda: compute(13)) == 13  # drops ("d1", 1)
    assert memo.get(("d1", 1), lambda: compute(14)) == 14
    assert calls == [10, 12, 13, 14]


def test_formation_digest_is_by_content() -> None:
    """Two formations built from one scenario share a digest; another graph or another
    vertex does not (the gain report is shared between the runs of a sweep by it)."""
    from dataclasses import replace
    from pathlib import Path

    import numpy as np

    from offboard.estimation.bearing import formation_from_scenario
    from swarm_common.scenario.model import load_scenario

    root = Path(__file__).resolve().parents[3]
    sc = load_scenario(root / "scenarios" / "cube8.toml")
    a, b = formation_from_scenario(sc), formation_from_scenario(sc)
    assert a is not b and a.content_digest() == b.content_digest()
    edge = next(iter(b.p_star))
    nudged = {**b.p_star, edge: b.p_star[edge] + 1e-12 * np.eye(3)}
    moved = replace(b, p_star=nudged, _digest=None)
    assert moved.content_digest() != a.content_digest()
    fewer = replace(b, neighbours=[list(n[:-1]) for n in b.neighbours], _digest=None)
    assert fewer.content_digest() != a.content_digest()
    other = formation_from_scenario(load_scenario(root / "scenarios" / "grid64.toml"))
    assert other.content_digest() != a.content_digest()
