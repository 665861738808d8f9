"""One agent's control step, shared by the in-process runner and the daemons.

Entry point: :func:`offboard.agent.factory.make_agent` returns a
:class:`~offboard.agent.follower.FollowerAgent` or a :class:`~offboard.agent.leader.LeaderAgent`;
both derive from :class:`offboard.agent.base.AgentBase`.

* :mod:`.takeoff`, :mod:`.landing` - coordinated take-off from pads and land-all.
* :mod:`.governor` - slows an infeasible leader trajectory until it fits the input set.
* :mod:`.peers` - whose estimates an agent needs and waits for.
* :mod:`.unsensed` - heard neighbours not sensed now whose rows come from prediction: in
  range by it, or beyond the range within the distance a pair must brake from.
* :mod:`.pair_inputs` - the pairs a part-by-part filter reads (sensed, then predicted).
* :mod:`.shares` - who takes a pair's whole avoidance budget (leaders, silent or
  non-cooperative neighbours).
* :mod:`.leader_guard` - a dcbf leader's filter against the scenario's non-cooperative
  agents, whose pairs with it nobody else keeps.
* :mod:`.detour` - the way out of a pocket of obstacles when a follower is stuck.
* :mod:`.guard`, :mod:`.fallback` - a follower's safety monitor, and the brake-hold-land it
  falls back to when its estimates diverge (beside the agents it senses, down to the ground).
"""
