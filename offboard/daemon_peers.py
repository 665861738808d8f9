"""Whose estimates a daemon subscribes to: its peers, from the scenario alone.

An agent reads the estimates of (docs/graphs.md):

* its bearing-graph neighbours (the DESO and the desired-state observer, paper §3);
* the leaders (the observer's leader anchor and the safety filter's feed-forward);
* every agent it senses in the desired formation (graph neighbours and every agent
  within ``formation.sensing_range_m``): the safety filter uses their accelerations and,
  for ``dcbf``, their predictions while a measurement drops out.

Nobody else's estimate can change its step, so a daemon subscribes to these keys only
(one key per peer, never a wildcard over the swarm) and waits for these agents only in
lockstep. On a small dense formation (cube8: every agent within 10 m of every other)
the peers are all the others; on a sparse one (``knn``, ``range``) they are a few, and
the messages a daemon receives per step no longer grow with the swarm.
"""

from __future__ import annotations

from offboard.bearing import Formation


def peer_ids(form: Formation, agent_id: int) -> list[int]:
    """The ids (sorted) whose estimates agent ``agent_id`` reads (module docstring)."""
    i = form.index_of(agent_id)
    sensed = form.sensed[i] if form.sensed else range(form.n)
    idx = set(form.neighbours[i]) | set(sensed) | set(form.leader_idx)
    idx.discard(i)
    return sorted(form.ids[j] for j in idx)
