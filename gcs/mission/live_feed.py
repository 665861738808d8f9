"""Feeding the live view (:class:`gcs.records.live.LiveView`, docs/records.md "Live
view") from each runner's own data: a step's rows as a :class:`~gcs.report.metrics.Series`
built by the functions that build a run's series
(:func:`~gcs.mission.run_output.set_truth_rows`, :func:`~gcs.mission.score.recorder_series`),
and each row's true attitudes.

* :class:`InprocFeed` - the in-process runner's rows, in batches (called by
  :func:`~gcs.mission.inproc.run_inproc` after each step);
* :func:`recorder_hook` - the distributed runner's ``on_step`` hook: the recorder's rows
  since its last call;
* :func:`feed_hook` - the dashboard's: each truth its Zenoh feed receives, with the newest
  status and estimate of every agent.

Each builds nothing while no client watches (:meth:`~gcs.records.live.LiveView.watched`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Protocol

import numpy as np

from gcs.mission.recorder import Recorder
from gcs.mission.run_output import empty_series, formation_yaw, set_truth_rows
from gcs.mission.score import recorder_series
from gcs.records.series import MAX_COUNT, STATUS_CODE, UNKNOWN_STATUS, rows_of
from gcs.report.metrics import Series
from offboard.estimation.bearing import Formation, formation_from_scenario
from swarm_common import wire
from swarm_common.enums import QPStatus
from swarm_common.scenario.model import Scenario

if TYPE_CHECKING:
    from gcs.records.live import LiveView

# the recorder's rows published per call at most (the newest; about a second of cube8):
# a call never costs more than that, however far the run went since the last one
MAX_ROWS = 50
INPROC_PERIOD_S = 1 / 30  # wall s between two batches of the in-process runner's rows
DEGRADED = frozenset(str(s) for s in QPStatus if s.degraded)  # QP statuses that fell back


class InprocFeed:
    """The in-process runner's feed: after each step :meth:`step` publishes the rows since
    the last batch, one batch every :data:`INPROC_PERIOD_S` of wall time (the runner goes
    faster than real time: the view gets every row, at a screen's rate, and the run pays
    for a batch of rows what one row costs)."""

    def __init__(self, sc: Scenario, form: Formation, live: LiveView) -> None:
        self.sc, self.form, self.live = sc, form, live
        self.shown = 0  # rows handed on (published, or passed while nobody watched)
        self.next_t = 0.0  # perf_counter() of the next batch

    def step(self, k: int, ser: Series, lumped: np.ndarray, thrust: np.ndarray,
             att: np.ndarray, last: bool = False) -> None:
        """Row ``k`` of ``ser`` is complete but for its truth rows, which the runner fills
        after the run (desired states, true disturbance, thrust, tilt): they come from its
        arrays ``lumped``, ``thrust`` and ``att`` here. ``last``: publish now."""
        now = time.perf_counter()
        if now < self.next_t and not last:
            return
        a, b = self.shown, k + 1
        self.shown, self.next_t = b, now + INPROC_PERIOD_S
        if not self.live.watched():
            return
        rows = rows_of(ser, slice(a, b))
        set_truth_rows(rows, self.form, rows.p, rows.v, lumped[a:b], thrust[a:b], att[a:b],
                       formation_yaw(self.sc, rows.p, rows.v))
        self.live.publish(rows, att[a:b])


def recorder_hook(sc: Scenario, rec: Recorder, live: LiveView) -> Callable[[int], None]:
    """The distributed runner's ``on_step(k)`` hook (``k``: the newest recorded step):
    publish the rows recorded since the last call up to k − 1 (the last whose statuses
    are in and whose minimum distance truth(k) carried), at most :data:`MAX_ROWS`. It runs
    on the runner's loop, the one that drains the recorder, between two drains."""
    form = formation_from_scenario(sc)
    done = [-1]  # the last row handed on (published or not watched)

    def on_step(k: int) -> None:
        ready = min(k, rec.steps) - 1
        if ready <= done[0]:
            return
        first, done[0] = max(done[0] + 1, ready - MAX_ROWS + 1), ready
        if not live.watched():
            return
        steps = np.arange(first, ready + 1)
        steps = steps[rec.have_truth[steps]]
        if len(steps):
            live.publish(recorder_series(rec, sc, steps, form), rec.att[steps].astype(float))

    return on_step


class FeedState(Protocol):
    """What the dashboard's feed holds (its ``FeedSnapshot``): each agent's newest status
    and estimate with their receive times."""

    @property
    def status(self) -> Mapping[int, tuple[wire.Status, float]]: ...

    @property
    def estimate(self) -> Mapping[int, tuple[wire.Estimate, float]]: ...


def feed_hook(sc: Scenario, live: LiveView, latest: Callable[[], FeedState]
              ) -> Callable[[wire.Truth], None]:
    """The dashboard's hook, called with each truth its feed receives: one row of that
    truth and the newest status and estimate of each agent (``latest()``; they may be a
    step off the truth, as the dashboard shows them), published."""
    form = formation_from_scenario(sc)
    col = {i: a for a, i in enumerate(sc.ids)}

    def on_truth(m: wire.Truth) -> None:
        if not live.watched() or list(m.ids) != list(sc.ids):
            return
        row = empty_series(np.array([float(m.t)]), sc.n, fill=np.nan)
        p, v = np.asarray(m.p, float)[None], np.asarray(m.v, float)[None]
        att = np.asarray(m.att, float)[None]
        set_truth_rows(row, form, p, v, np.asarray(m.lumped, float)[None],
                       np.asarray(m.thrust, float)[None], att, formation_yaw(sc, p, v))
        row.min_dist[0] = m.min_dist  # over the period before t (a row's is the one after)
        state = latest()
        for i, (st, _) in state.status.items():
            if (a := col.get(i)) is None:
                continue
            row.u[0, a], row.lumped_est[0, a] = st.u, st.lumped
            row.h_min[0, a], row.solve_us[0, a] = st.h_min, st.qp_solve_us
            row.fallback[0, a] = st.qp_status in DEGRADED
            row.input_clipped[0, a], row.alarms[0, a] = bool(st.input_clipped), st.alarms & 0xFF
            row.qp_status[0, a] = STATUS_CODE.get(st.qp_status, UNKNOWN_STATUS)
            row.qp_active[0, a] = min(max(st.qp_active, 0), MAX_COUNT)
            row.qp_kinds[0, a], row.u_nom[0, a] = st.qp_kinds & 0xFF, st.u_nom
            row.clf_slack[0, a], row.qp_relax[0, a] = st.qp_slack, st.qp_relax
            row.u_corr[0, a] = st.correction
        for i, (e, _) in state.estimate.items():
            if (a := col.get(i)) is not None:
                row.z1[0, a], row.z2[0, a], row.xi_p[0, a] = e.z1, e.z2, e.xi[:3]
        live.publish(row, att)

    return on_truth
