"""A leader's guard against the non-cooperative agents of its scenario (docs/safety.md §5b).

Leaders never avoid anyone in the paper: every follower takes the whole avoidance budget
against a leader. A follower that does not cooperate (``[[agent]] cooperative = false``:
it flies its nominal command with no filter) leaves its pairs with the leaders to nobody.
So a dcbf leader takes the whole budget against exactly those agents. It senses them as a
follower does (:class:`~offboard.estimation.sensing.Sensor`, its own seeded stream, and
the dropout hold), and its command goes through the product's filter,
:class:`~offboard.safety.dcbf.filter.DcbfFilter`, with one pair of rows per sensed
non-cooperative agent, its own truth odometry as its state, its velocity ESO's
disturbance as w, and no CLF: the nominal command is the leader's tracking law, and the
QP keeps it wherever the rows allow. The claim of §5 then covers the leader–rogue pair
under the same assumptions as a follower–rogue pair (A3 for the rogue: its acceleration
within ē of what the rows predict).

Only the agents that the scenario declares non-cooperative are guarded against: every
agent knows them from the file, so leaders need no estimate of anyone and, in lockstep,
wait for no one (offboard.agent.peers). A leader with another method, or in a scenario
without such agents, has no guard and flies exactly as before.
"""

from __future__ import annotations

import numpy as np

from offboard.estimation.sensing import DropoutHold, Sensor
from offboard.records import AgentStatus
from offboard.safety.base import SafetyInput
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from swarm_common.scenario.model import Scenario

# how long a dropped measurement of a guarded agent keeps its rows (s), as a follower's
SENSE_HOLD_S = 0.5


def guarded_indices(sc: Scenario, index: int) -> np.ndarray:
    """Scenario indices of the agents a leader at ``index`` guards against: the
    non-cooperative ones (never itself)."""
    return np.array([j for j, a in enumerate(sc.agents) if not a.cooperative and j != index],
                    dtype=np.int64)


class LeaderGuard:
    """The dcbf filter of a leader against the scenario's non-cooperative agents (module
    docstring). :meth:`apply` filters the leader's command; :meth:`realised` keeps the
    inner-loop model's output that the next step's rows predict from."""

    def __init__(
        self, sc: Scenario, index: int, agent_id: int, seed: int, u_lo: np.ndarray,
        u_hi: np.ndarray, guarded: np.ndarray,
    ) -> None:
        n = sc.n
        self.index = index
        self.mask = np.zeros(n, dtype=bool)
        self.mask[guarded] = True
        self.sensor = Sensor(index, agent_id, n, sc.sensing, sc.formation.sensing_range_m, seed)
        self.hold = DropoutHold(n, index, SENSE_HOLD_S, sc.sensing.dropout_prob > 0.0)
        # no agent is a leader to this filter: the leader takes every guarded pair whole
        self.filter = DcbfFilter(sc.controller, u_lo, u_hi, np.zeros(n, dtype=bool))
        self.filter.configure(sc.vehicle, sc.control_dt)
        self.a_real = np.zeros(3)  # the inner-loop model's realised control (m/s²)
        self.a_mean = np.zeros(3)  # ... its mean over the last period
        self.u_prev = np.zeros(3)  # the command of the step before (m/s²)
        self._no_clf = np.zeros(3)

    def apply(
        self, t: float, truth_p: np.ndarray, truth_v: np.ndarray, u_nom: np.ndarray,
        w: np.ndarray, status: AgentStatus,
    ) -> np.ndarray:
        """The command (m/s²) for the leader's nominal ``u_nom`` at ``t`` (s), given every
        agent's (N,3) truth position and velocity (what its sensor reads) and its own
        disturbance estimate ``w`` (m/s²); the step's filter report goes into ``status``.
        ``u_nom`` itself when no guarded agent is sensed (the filter is not called)."""
        meas = self.sensor.measure(truth_p, truth_v)
        sel, rp, rv = self.hold.pairs(t, meas.valid, meas.rel_pos(), meas.rel_vel())
        sel = sel[self.mask[sel]]
        status.n_sensed = len(sel)
        if len(sel) == 0:
            return u_nom
        p, v = truth_p[self.index], truth_v[self.index]
        x = SafetyInput(
            clf=ClfTerms(0.0, 0.0, self._no_clf, u_nom), w=w, z2=np.array(v, dtype=float),
            dp=-np.asarray(rp[sel], dtype=float), dv=-np.asarray(rv[sel], dtype=float),
            pairs=sel, lead_acc={}, a_real=self.a_real, u_prev=self.u_prev, a_mean=self.a_mean,
            other_acc=None, full_share=np.ones(len(sel), dtype=bool),
            z1=np.array(p, dtype=float), floor_m=None,
        )
        res = self.filter.apply(x)
        res.report_into(status, res.u)
        if not np.all(np.isfinite(res.u)):  # never fly a non-finite command: keep the nominal
            status.fallbacks += 1
            return u_nom
        return res.u

    def realised(self, u: np.ndarray, a_real: np.ndarray, a_mean: np.ndarray) -> None:
        """The step's command ``u`` and the inner-loop model's realised control at the end
        of the period and its mean over it (m/s²): what the next step predicts from."""
        self.u_prev = np.array(u, dtype=float)
        self.a_real = np.array(a_real, dtype=float)
        self.a_mean = np.array(a_mean, dtype=float)


def leader_guard(
    sc: Scenario, index: int, agent_id: int, seed: int, u_lo: np.ndarray, u_hi: np.ndarray,
) -> LeaderGuard | None:
    """The guard of a leader in a scenario with non-cooperative agents, else None (the
    leader applies it while its method is dcbf)."""
    guarded = guarded_indices(sc, index)
    if len(guarded) == 0:
        return None
    return LeaderGuard(sc, index, agent_id, seed, u_lo, u_hi, guarded)
