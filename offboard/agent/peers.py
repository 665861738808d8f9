"""Whose estimates a daemon subscribes to, and whom it waits for before flying: from the
scenario alone.

A follower reads the estimates of (docs/graphs.md):

* its bearing-graph neighbours (the DESO and the desired-state observer, paper §3);
* the leaders (the observer's leader anchor and the safety filter's feed-forward);
* every agent it senses in the desired formation (graph neighbours and every agent
  within ``formation.sensing_range_m``): the safety filter uses their accelerations and,
  for ``dcbf``, their predictions while a measurement drops out.

Nobody else's estimate can change its step, so a follower subscribes to these keys only
(one key per peer, never a wildcard over the swarm) and waits for these agents only in
lockstep. On a small dense formation (cube8: every agent within 10 m of every other)
the peers are all the others; on a sparse one (``knn``, ``range``) they are a few, and
the messages a daemon receives per step no longer grow with the swarm.

A leader reads no estimate: it flies its own (governed) trajectory with its own state
(Departure 4), so nobody's estimate can change its step. It subscribes to none once
flying and never waits for one in lockstep. Before its first step it still waits, like a
follower, until it has heard from the agents of :func:`ready_ids` (the arming policy,
:class:`offboard.daemon.mavlink.mode_requests.SwarmReady`): a leader must not start the trajectory
while
the followers that track it are not up.
"""

from __future__ import annotations

from offboard.estimation.bearing import Formation


def ready_ids(form: Formation, agent_id: int) -> list[int]:
    """The ids (sorted) agent ``agent_id`` must hear from before its first step: its graph
    neighbours, the leaders and the agents it senses in the formation (any role)."""
    i = form.index_of(agent_id)
    sensed = form.sensed[i] if form.sensed else range(form.n)
    idx = set(form.neighbours[i]) | set(sensed) | set(form.leader_idx)
    idx.discard(i)
    return sorted(form.ids[j] for j in idx)


def peer_ids(form: Formation, agent_id: int) -> list[int]:
    """The ids (sorted) whose estimates agent ``agent_id`` reads and, in lockstep, awaits
    each step (module docstring): :func:`ready_ids` for a follower, none for a leader."""
    if form.index_of(agent_id) in form.leader_idx:
        return []
    return ready_ids(form, agent_id)
