"""The collector's frozen block (swarm_common.process_life.frozen_while)."""

from __future__ import annotations

import gc

from swarm_common.process_life import frozen_while

# The objects are matched by ``type(o) is Node``: ``gc.get_objects()`` also lists the weak
# proxies other tests of the process left, and ``isinstance`` on one whose referent is
# gone raises ReferenceError (it did in a serial run of tests/unit/common).


class Node:
    """An object in a reference cycle: only the cyclic collector frees it."""

    def __init__(self) -> None:
        self.me = self


def test_a_frozen_block_skips_what_was_alive_and_gives_it_back() -> None:
    gc.collect()
    before = Node()
    assert gc.get_freeze_count() == 0
    with frozen_while():
        frozen = gc.get_freeze_count()
        assert frozen > 0  # everything alive on entry, the cycle among it
        made = Node()  # made inside: the collections inside see it and free it
        del made
        gc.collect()
        assert [o for o in gc.get_objects() if type(o) is Node] == []  # frozen: unseen
        assert gc.get_freeze_count() == frozen
    assert gc.get_freeze_count() == 0  # back to the collector after the block
    alive = [id(o) for o in gc.get_objects() if type(o) is Node]
    assert id(before) in alive
    del before
    gc.collect()
    assert not [o for o in gc.get_objects() if type(o) is Node]  # collected after it


def test_a_frozen_process_stays_frozen() -> None:
    kept = Node()  # alive and tracked: frozen with the rest below
    gc.freeze()
    try:
        assert not any(o is kept for o in gc.get_objects())  # frozen: the collector skips it
        with frozen_while():
            pass
        # the start-up's freeze is not undone: what it froze is still frozen (the count of
        # frozen objects itself may fall meanwhile, as other threads free some of them)
        assert gc.get_freeze_count() > 0
        assert not any(o is kept for o in gc.get_objects())
    finally:
        gc.unfreeze()
    assert any(o is kept for o in gc.get_objects())  # back to the collector
