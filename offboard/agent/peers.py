"""Whose estimates a daemon subscribes to, and whom it waits for before flying: from the
scenario alone.

A follower reads the estimates of (docs/graphs.md):

* its bearing-graph neighbours (the DESO and the desired-state observer, paper §3);
* every agent it senses in the desired formation (graph neighbours and every agent
  within ``formation.sensing_range_m``): the safety filter uses their accelerations and,
  for ``dcbf``, their predictions while a measurement drops out or before they come into
  range. The leaders among them are the ones the observer's leader anchor uses (D21) and
  whose acceleration the rcbf filter takes as known (Departure 13).

Nobody else's estimate can change its step, so a follower subscribes to these keys only
(one key per peer, never a wildcard over the swarm) and waits for these agents only in
lockstep. A leader that is neither a neighbour nor sensed in the formation is not a peer:
the observers give it no weight, and a pair with it relies on the sensing range, as any
pair that does not hear each other does (docs/safety.md §5j). At a thousand agents every
follower used to read all 64 leaders, most of its step's rows, the largest part of a
step that grew with the swarm (docs/performance.md). On a small dense formation (cube8:
every agent within 10 m of every other) the peers are all the others; on a sparse one
(``knn``, ``range``) they are a few, and the messages a daemon receives per step no longer
grow with the swarm.

A leader reads no estimate: it flies its own (governed) trajectory with its own state
(Departure 4), so nobody's estimate can change its step. It subscribes to none once
flying and never waits for one in lockstep. Before its first step every agent, leader or
follower, waits until it has heard from the agents of :func:`ready_ids`, every leader
among them (the arming policy,
:class:`offboard.daemon.mavlink.mode_requests.SwarmReady`): a leader must not start the
trajectory while the followers that track it are not up, nor a follower fly before the
formation's leaders are.
"""

from __future__ import annotations

from offboard.estimation.bearing import Formation


def _heard(form: Formation, i: int) -> set[int]:
    """The scenario indices follower ``i`` reads: its graph neighbours and the agents it
    senses in the formation (everyone when the formation sets no range), not itself."""
    sensed = form.sensed[i] if form.sensed else range(form.n)
    idx = set(form.neighbours[i]) | set(sensed)
    idx.discard(i)
    return idx


def ready_ids(form: Formation, agent_id: int) -> list[int]:
    """The ids (sorted) agent ``agent_id`` must hear from before its first step: its graph
    neighbours, the leaders and the agents it senses in the formation (any role)."""
    i = form.index_of(agent_id)
    idx = _heard(form, i) | set(form.leader_idx)
    idx.discard(i)
    return sorted(form.ids[j] for j in idx)


def peer_ids(form: Formation, agent_id: int) -> list[int]:
    """The ids (sorted) whose estimates agent ``agent_id`` reads and, in lockstep, awaits
    each step (module docstring): for a follower its graph neighbours and the agents it
    senses in the formation, none for a leader."""
    i = form.index_of(agent_id)
    if i in form.leader_idx:
        return []
    return sorted(form.ids[j] for j in _heard(form, i))
