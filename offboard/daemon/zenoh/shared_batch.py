"""The received estimates of a packed process's daemons as one batch per step.

A daemon hands its agent the estimates it received for step k−1 as an
:class:`~offboard.estimation.peer_table.EstimateBatch` of all N agents by scenario index
(:func:`offboard.daemon.wire_convert.estimates_from_wire`): one row per received estimate, NaN
stamps elsewhere. In a packed grid64 process that is 64 batches of about 14 rows per step,
19 µs per agent-step (docs/performance.md, "Issue 11, thirteenth round"). Yet the
process decodes each payload once, and its daemons accept the same decoded objects
(:class:`offboard.daemon.zenoh.link.DecodeCache`): most rows are the same row, built 14 times.

:class:`SharedBatch` keeps one batch per step for the process's daemons, each row put
from one decoded estimate object. An agent reads only its peers' rows (a follower
ingests the rows of its peer indices, as from the in-process runner's batch of all
agents; a leader reads none). So a daemon may be handed the shared batch when, for each
of its peers, the shared row is exactly what it received: a row from the very object it
accepted, or no row where it received nothing. Otherwise it gets a batch of its own, as
before: when another daemon accepted a different payload for the same agent and step,
or when the batch holds a row of a peer this daemon did not receive. Either way its agent
reads the same numbers.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from offboard.daemon.wire_convert import estimates_from_wire, put_row
from offboard.estimation.peer_table import EstimateBatch
from swarm_common import wire


class SharedBatch:
    """One :class:`EstimateBatch` per step for the daemons of a packed process (module
    docstring); ``index_of``: agent id → scenario index of the ``n`` agents."""

    def __init__(self, index_of: Mapping[int, int]) -> None:
        self.index_of = dict(index_of)
        self.n = len(self.index_of)
        self.step: int | None = None
        self.batch = EstimateBatch.empty(self.n)
        self.source: list[wire.Estimate | None] = [None] * self.n  # each row's payload

    def batch_for(
        self, step: int, received: Mapping[int, wire.Estimate], peers: np.ndarray
    ) -> EstimateBatch:
        """The batch a daemon hands its agent for the estimates ``received`` (by id) of
        ``step``; ``peers``: the scenario indices of the agents its agent reads."""
        if step != self.step:
            self.step = step
            self.batch = EstimateBatch.empty(self.n)  # a fresh object: never one in use
            self.source = [None] * self.n
        own = self._own(received)
        if own is not None:
            return own
        source = self.source
        for j in peers:
            got = source[j]
            if got is not None and received.get(got.id) is not got:
                return estimates_from_wire(self.index_of, self.n, received)
        return self.batch

    def _own(self, received: Mapping[int, wire.Estimate]) -> EstimateBatch | None:
        """Put the received rows the shared batch lacks; a batch of the daemon's own when
        one of them conflicts with a row already there, else None."""
        b, source = self.batch, self.source
        for aid, e in received.items():
            j = self.index_of.get(aid)
            if j is None or source[j] is e:
                continue
            if source[j] is not None:  # another payload for this agent and step
                return estimates_from_wire(self.index_of, self.n, received)
            put_row(b, j, e)
            source[j] = e
        return None
