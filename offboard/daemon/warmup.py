"""Load the compiled kernels (:mod:`swarm_common.jit`) before a daemon's first step.

A numba kernel is loaded from its on-disk cache (or compiled, on a machine's first run)
on its first call in a process: 0.3–0.5 s of CPU for the follower's kernels, 2–5 s when
compiling. Left to the first control step, that time lands inside the control loop: a
late first answer in real time, and a start-up cost counted as control. :func:`warm_kernels`
steps throwaway agents of the scenario (one follower, through its dcbf step in one
compiled call, and one leader) for a few control periods on the scenario's initial state,
the last of them silent as in an outage, before the daemon starts, so the real agents' first
step runs loaded code. The throwaway agents share nothing with the real ones but the
process-wide caches (gain reports, propagators), and their log lines are muted.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from offboard.agent.factory import make_agent
from offboard.estimation.bearing import Formation
from offboard.estimation.reference import xi_at_rest
from offboard.records import NeighbourEstimate
from swarm_common.scenario.model import Scenario

PERIODS = 3  # control periods each throwaway agent is stepped hearing its neighbours

log = logging.getLogger(__name__)


def warm_kernels(sc: Scenario, method: str | None, form: Formation) -> float:
    """Step a throwaway follower and leader of ``sc`` (``method``) for :data:`PERIODS`
    periods at rest on the initial state, then one silent period (the neighbours' data
    predicted); returns the CPU time it took (s). The warm-up is an optimisation: if it
    fails, a warning says why and the daemon starts as it would without it (its kernels
    then load on the first step)."""
    t0 = time.process_time()
    try:
        _step_throwaway_agents(sc, method, form)
    except Exception as exc:  # noqa: BLE001 - never stop a daemon for its warm-up
        log.warning("kernel warm-up skipped (%s: %s)", type(exc).__name__, exc)
    cpu = time.process_time() - t0
    log.debug("kernels loaded in %.2f s of CPU", cpu)
    return cpu


def _step_throwaway_agents(sc: Scenario, method: str | None, form: Formation) -> None:
    """The warm-up itself (:func:`warm_kernels`)."""
    p = np.array([a.position for a in sc.agents], dtype=float)
    v = np.zeros_like(p)
    lead = set(sc.leader_ids)
    ests = {a.id: NeighbourEstimate(a.id, 0.0, p[i].copy(), np.zeros(3), np.zeros(3),
                                    xi_at_rest(p[i]), a.id in lead)
            for i, a in enumerate(sc.agents)}
    ids = [sc.follower_ids[0]] if sc.follower_ids else []
    ids += [sc.leader_ids[0]] if sc.leader_ids else []
    previous = logging.root.manager.disable
    logging.disable(logging.INFO)  # the throwaway agents' start-up lines are not the run's
    try:
        for aid in ids:
            agent = make_agent(sc, aid, method=method, seed=sc.seed, form=form)
            for k in range(PERIODS + 1):
                t = k * sc.control_dt
                nbrs = {j: NeighbourEstimate(e.id, t, e.z1, e.z2, e.z3, e.xi, e.is_leader)
                        for j, e in ests.items() if j != aid}
                # the last period silent, as in an outage: the neighbours' data is a
                # period old and predicted (offboard.estimation.predictor.predict_row_into)
                agent.step(k, t, p, v, nbrs, k < PERIODS)
    finally:
        logging.disable(previous)
