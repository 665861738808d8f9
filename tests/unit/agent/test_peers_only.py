"""A follower's step reads its peers' estimates only (offboard.agent.peers): on a sparse
formation, whatever the others publish, a far leader's included, its outputs are the same
bits."""

from __future__ import annotations

import numpy as np

from gcs.mission.agents.wire_form import published_batch
from offboard.agent.factory import FollowerAgent, make_agent
from offboard.agent.peers import peer_ids
from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.peer_table import EstimateBatch
from swarm_common.scenario.model import load_scenario

SC = load_scenario("scenarios/grid27_knn.toml")
STEPS = 60  # 1.2 s: past the 0.5 s after which heard agents beyond range get rows


def _lying(batch: EstimateBatch, keep: set[int], at: np.ndarray) -> EstimateBatch:
    """``batch`` with every row outside ``keep`` (scenario indices) replaced by an
    estimate 0.3 m from ``at`` (m), closing at 4 m/s: an agent about to hit the
    follower, were it heard."""
    rows = batch.rows.copy()
    out = [j for j in range(len(rows)) if j not in keep]
    rows[out, 0:3] = at + 0.3
    rows[out, 3:6] = -4.0
    return EstimateBatch(batch.t.copy(), rows, batch.leader.copy(), batch.cooperative.copy())


def test_a_follower_ignores_what_its_non_peers_publish() -> None:
    form = formation_from_scenario(SC)
    honest = [make_agent(SC, a.id, method="dcbf", form=form) for a in SC.agents]
    fooled = [make_agent(SC, a.id, method="dcbf", form=form) for a in SC.agents]
    # what it may read: its graph neighbours and the agents it senses in the formation
    peers = {i: set(form.neighbours[form.index_of(i)]) | set(form.sensed[form.index_of(i)])
             for i in SC.ids}
    assert all(peers[i] - {form.index_of(i)} == {form.index_of(j) for j in peer_ids(form, i)}
               for i in SC.ids if i not in SC.leader_ids)
    # the formation has followers with leaders that are not their peers
    far = [i for i in SC.ids if i not in SC.leader_ids
           and set(form.leader_idx) - peers[i] - {form.index_of(i)}]
    assert far
    p0 = SC.initial_positions()
    dt = SC.control_dt
    pub = published_batch([ag.initial_estimate() for ag in honest])
    for k in range(STEPS):
        t = k * dt
        tp = (p0 + 0.2 * np.sin(0.5 * t + np.arange(SC.n))[:, None]).astype(np.float32)
        tv = np.full_like(tp, 0.1)
        outs_h = [ag.step(k, t, tp, tv, pub, True) for ag in honest]
        for ag, oh in zip(fooled, outs_h, strict=True):
            if not isinstance(ag, FollowerAgent):
                continue
            i = form.index_of(ag.id)
            od = ag.step(k, t, tp, tv, _lying(pub, peers[ag.id], tp[i]), True)
            assert np.array_equal(oh.q_ned, od.q_ned) and oh.thrust_norm == od.thrust_norm
            for f in ("z1", "z2", "z3", "xi"):
                assert np.array_equal(getattr(oh.estimate, f), getattr(od.estimate, f)), (k, f)
            assert oh.status.alarms == od.status.alarms
        pub = published_batch([o.estimate for o in outs_h])
