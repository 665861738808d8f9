"""offboard.identity_memo: once per (object, parameters), by identity, bounded."""

from __future__ import annotations

from offboard.identity_memo import IdentityMemo


def test_computed_once_per_object_and_parameters() -> None:
    memo: IdentityMemo[int] = IdentityMemo(size=2)
    calls: list[int] = []

    def compute(v: int) -> int:
        calls.append(v)
        return v

    a, b = [1], [1]  # equal, but two objects
    assert memo.get(a, "p", lambda: compute(10)) == 10
    assert memo.get(a, "p", lambda: compute(11)) == 10  # cached
    assert memo.get(a, "q", lambda: compute(12)) == 12  # other parameters
    assert memo.get(b, "p", lambda: compute(13)) == 13  # other object, though equal
    assert calls == [10, 12, 13]
    # size 2: the oldest entry (a, "p") was dropped for (b, "p")
    assert memo.get(a, "p", lambda: compute(14)) == 14
