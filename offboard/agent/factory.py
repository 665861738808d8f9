"""Per-agent control step: the ONE object the in-process runner and the daemon both call.

Interface (all vectors ENU, z up; agents addressed by id, arrays in scenario order)::

    agent = make_agent(sc, agent_id, method="rcbf", seed=None)   # FollowerAgent | LeaderAgent
    est0 = agent.initial_estimate()          # NeighbourEstimate valid for t_0 (publish first)
    out = agent.step(k, t, truth_p, truth_v, neighbours, comm_ok)   # -> AgentOutput
    agent.set_method(Method.APF)             # a Method (or its string), at run time
    agent.gains                              # DESO GainReport (followers), print .lines()

* ``truth_p``/``truth_v``: (N,3) float32-rounded ground truth of all agents at t_k. A
  follower uses them ONLY through its :class:`~offboard.estimation.sensing.Sensor` (relative
  bearing/range measurements); it never reads its own row. A leader reads its own row.
* ``neighbours``: {id: NeighbourEstimate} published by the others at step k−1 (post-update,
  i.e. valid for t_k). Missing entries or ``comm_ok=False`` (outage, Departure 16): the agent
  predicts the last received data to t_k (constant velocity for followers' z, the
  exosystem for ξ and for leaders' broadcast state).
* ``AgentOutput``: the attitude/thrust setpoint (as decoded from the float32 wire form),
  the MAVLink payload (``q_ned`` wxyz float32, ``thrust_norm`` float32), ``u`` (ENU
  virtual control), ``estimate`` (to publish, valid for t_{k+1}) and ``status``.

Follower step k: sense (t_k) → predict neighbours to t_k → controller on (z(t_k), ξ̂(t_k))
→ safety filter of the method → setpoint → inner-loop model → DESO and desired-state
observer advanced to t_{k+1} → publish. Leader step k: PD + feed-forward on its own
trajectory with a small velocity ESO for its disturbance; publishes its state predicted
for t_{k+1} and ξ_L(t_{k+1}).

Modules: :mod:`offboard.records` (the records), :mod:`offboard.agent.base` (shared
setup), :mod:`offboard.agent.follower`, :mod:`offboard.agent.leader`,
:mod:`offboard.estimation.predictor`
(neighbour ageing) and :mod:`offboard.safety.filter` (one class per method).
"""

from __future__ import annotations

from offboard.agent.base import AgentBase
from offboard.agent.follower import FollowerAgent
from offboard.agent.leader import LeaderAgent
from offboard.estimation.bearing import Formation
from offboard.estimation.predictor import NeighbourPredictor
from offboard.inner_loop.attitude import accel_from_attitude
from offboard.records import AgentOutput, AgentStatus, NeighbourEstimate
from swarm_common.enums import Method, Role
from swarm_common.scenario.model import Scenario

AGENT_CLASSES: dict[Role, type[FollowerAgent] | type[LeaderAgent]] = {
    Role.LEADER: LeaderAgent,
    Role.FOLLOWER: FollowerAgent,
}


def make_agent(
    sc: Scenario, agent_id: int, method: Method | str | None = None, seed: int | None = None,
    form: Formation | None = None,
) -> FollowerAgent | LeaderAgent:
    """The agent object for ``agent_id`` (class by its role in the scenario)."""
    cls = AGENT_CLASSES[sc.agents[sc.index_of(agent_id)].role]
    return cls(sc, agent_id, method=method, seed=seed, form=form)


__all__ = [
    "AGENT_CLASSES",
    "AgentBase",
    "AgentOutput",
    "AgentStatus",
    "FollowerAgent",
    "LeaderAgent",
    "NeighbourEstimate",
    "NeighbourPredictor",
    "accel_from_attitude",
    "make_agent",
]
