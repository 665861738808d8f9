"""The recorder of a distributed run: Zenoh truth, estimates and statuses per control step.

Memory is allocated once, at the start, for the run's ``steps`` (float32: the values that
crossed the wire are float32, so nothing is lost), and never grows with the run: the
subscribers queue the payloads in Zenoh's own channels (no Python runs on Zenoh's
threads, so the router never waits for the interpreter), which the runner's loop drains
(:meth:`Recorder.drain`) into the preallocated arrays every few tens of milliseconds.
A payload that does not decode, names an agent outside the scenario, carries a step
outside the run or non-finite values is dropped and counted (``dropped``). The
ground-station commands on the swarm's ``cmd/*`` keys are kept for the run's audit trail
(``commands``, :func:`gcs.mission.audit.zenoh_record`; the first
:data:`gcs.mission.audit.ZENOH_CAP`, then counted in ``commands_dropped``).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import zenoh

from gcs.mission.audit import ZENOH_CAP, zenoh_record
from gcs.records.series import MAX_COUNT, STATUS_CODE, UNKNOWN_STATUS
from offboard.daemon.link_guard import all_finite
from offboard.daemon.zenoh.link import ZENOH_ERRORS
from swarm_common import wire
from swarm_common.enums import QPStatus
from swarm_common.scenario.model import Scenario

F32 = np.float32
# payloads a subscriber's channel holds between two drains (every 50 ms, longer during a
# checkpoint): at 17 per step and 5x real time, about a minute of cube8 (a full channel
# would make the router wait)
CHANNEL_DEPTH = 1 << 18


class TruthView(Mapping[int, wire.Truth]):
    """``step -> wire.Truth`` over the recorder's arrays (the steps that arrived)."""

    def __init__(self, rec: Recorder) -> None:
        self._rec = rec

    def __getitem__(self, k: int) -> wire.Truth:
        r = self._rec
        if not (0 <= k < len(r.have_truth)) or not r.have_truth[k]:
            raise KeyError(k)
        return wire.Truth(
            step=k, t=float(r.t[k]), ids=list(r.sc.ids), p=r.p[k].astype(float),
            v=r.v[k].astype(float), att=r.att[k].astype(float),
            thrust=r.thrust[k].astype(float), lumped=r.lumped_true[k].astype(float),
            collisions=int(r.collisions[k]), min_dist=float(r.min_dist[k]),
            mode=list(r.last_mode) if k == r.max_step else [],
        )

    def __iter__(self) -> Iterator[int]:
        return iter(np.flatnonzero(self._rec.have_truth).tolist())

    def __len__(self) -> int:
        return int(np.count_nonzero(self._rec.have_truth))


class Recorder:
    """Collects the Zenoh traffic of a run, indexed by control step (0..steps)."""

    def __init__(self, sc: Scenario, steps: int, seed: int | None = None) -> None:
        self.sc, self.steps, self.seed = sc, steps, seed
        self.idx = {a.id: i for i, a in enumerate(sc.agents)}
        n, rows = sc.n, steps + 2

        def arr(*shape: int) -> np.ndarray:
            return np.full((rows, *shape), np.nan, F32)

        self.t = np.full(rows, np.nan)
        self.min_dist = np.full(rows, np.nan)
        self.collisions = np.zeros(rows, np.int32)
        self.have_truth = np.zeros(rows, bool)
        self.p, self.v, self.att, self.lumped_true = arr(n, 3), arr(n, 3), arr(n, 3), arr(n, 3)
        self.thrust = arr(n)
        # estimates published at step k in row k + 1 (row 0: the initial ones, step −1),
        # i.e. row k holds the estimates valid at t_k
        self.z1, self.z2 = arr(n, 3), arr(n, 3)
        self.xi_p = arr(n, 3)  # the desired position each agent estimates (ξ̂_p)
        self.u, self.lumped_est = arr(n, 3), arr(n, 3)  # statuses of step k
        self.h_min, self.solve_us = arr(n), arr(n)
        self.degraded = np.zeros((rows, n), bool)
        self.clipped = np.zeros((rows, n), bool)
        self.alarms = np.zeros((rows, n), np.uint8)  # AgentAlarm bits of step k
        # the safety filter's report of step k (gcs.records.series.RunSeries)
        self.qp_status = np.full((rows, n), UNKNOWN_STATUS, np.uint8)
        self.qp_active, self.qp_kinds = np.zeros((rows, n), np.uint8), np.zeros((rows, n), np.uint8)
        self.clf_slack, self.qp_relax, self.u_corr = arr(n), arr(n), arr(n)
        self.u_nom = arr(n, 3)
        self.have_status = np.zeros((rows, n), bool)
        self.zeta_last = np.zeros((n, 6))  # ζ̂ of the estimates of step steps-1
        self.last_status: dict[int, wire.Status] = {}
        self.lock = threading.Lock()
        self.max_step = -1
        self.last_mode: list[str] = []
        self.dropped = 0
        self.commands: list[dict[str, Any]] = []  # Zenoh commands seen (audit records)
        # the vehicles' stored fences as they changed (wire.Truth.fences): (time s,
        # column, outline), what the verdict scores from then (gcs.report.world_metrics)
        self.fence_changes: list[tuple[float, int, tuple[float, ...]]] = []
        self.commands_dropped = 0
        self._subs: list[Any] = []

    @property
    def truth(self) -> TruthView:
        return TruthView(self)

    def subscribe(self, session: Any, swarm: str) -> list[Any]:
        """Declare the truth, estimate, status and command subscribers on ``session``
        (each with its channel, read by :meth:`drain`)."""
        self._subs = [
            session.declare_subscriber(key, zenoh.handlers.FifoChannel(CHANNEL_DEPTH))
            for key in (wire.key_truth(swarm), wire.key_estimate(swarm, "*"),
                        wire.key_status(swarm, "*"), wire.key_cmd(swarm, "*"))
        ]
        return self._subs

    def _received(self) -> list[tuple[str, bytes]]:
        """Every (key, payload) waiting in the subscribers' channels (the loop of
        :meth:`offboard.daemon.zenoh.link.SwarmBus.pump`, without its per-sample handler)."""
        out: list[tuple[str, bytes]] = []
        for sub in self._subs:
            while True:
                try:
                    sample = sub.try_recv()
                except ZENOH_ERRORS:  # undeclared: nothing more to read
                    break
                if sample is None:
                    break
                out.append((str(sample.key_expr), sample.payload.to_bytes()))
        return out

    def _put_truth(self, m: wire.Truth) -> bool:
        k = m.step
        if not (0 <= k <= self.steps) or list(m.ids) != self.sc.ids:
            return False
        if not all_finite((m.p, m.v, m.att, m.lumped, m.thrust)) or not np.isfinite(m.t):
            return False
        self.t[k], self.min_dist[k], self.collisions[k] = m.t, m.min_dist, m.collisions
        self.p[k], self.v[k], self.att[k], self.lumped_true[k] = m.p, m.v, m.att, m.lumped
        self.thrust[k] = m.thrust
        self.have_truth[k] = True
        for aid, xy in m.fences.items():  # ids checked by the decoder
            self.fence_changes.append((float(m.t), self.idx[aid], tuple(map(float, xy))))
        if k >= self.max_step:  # the vehicles' modes of the newest truth (not kept per step)
            self.last_mode = [str(x) for x in m.mode]
        self.max_step = max(self.max_step, k)
        return True

    def drain(self) -> None:
        """Decode the payloads received since the last call into the arrays."""
        dropped = 0
        for key, data in self._received():
            try:
                msg = wire.decode(data)
            except wire.WireError:
                dropped += 1
                continue
            if isinstance(msg, wire.Command):
                self._put_command(key, msg)
                continue
            if isinstance(msg, wire.Truth):
                with self.lock:
                    dropped += not self._put_truth(msg)
                continue
            i = self.idx.get(getattr(msg, "id", -1))
            k = getattr(msg, "step", -1)
            if isinstance(msg, wire.Estimate) and i is not None and k == -1:
                dropped += not self._put_estimate(msg, k, i)  # the initial estimates
            elif i is None or not (0 <= k <= self.steps):
                dropped += 1
            elif isinstance(msg, wire.Estimate):
                dropped += not self._put_estimate(msg, k, i)
            elif isinstance(msg, wire.Status):
                dropped += not self._put_status(msg, k, i)
            else:
                dropped += 1
        with self.lock:
            self.dropped += dropped

    def _put_command(self, key: str, cmd: wire.Command) -> None:
        """An audit record of a command, at the mission time of the newest truth."""
        if len(self.commands) >= ZENOH_CAP:
            self.commands_dropped += 1
            return
        with self.lock:
            k = self.max_step
            t = float(self.t[k]) if k >= 0 else -1.0
        self.commands.append(zenoh_record(t, key, cmd))

    def _put_estimate(self, e: wire.Estimate, k: int, i: int) -> bool:
        if not all_finite((e.z1, e.z2)):
            return False
        self.z1[k + 1, i], self.z2[k + 1, i] = e.z1, e.z2
        self.xi_p[k + 1, i] = e.xi[:3]
        if k == self.steps - 1 and np.all(np.isfinite(e.zeta)):
            self.zeta_last[i] = e.zeta
        return True

    def _put_status(self, st: wire.Status, k: int, i: int) -> bool:
        try:
            degraded = QPStatus(st.qp_status).degraded
        except ValueError:
            return False
        self.u[k, i], self.lumped_est[k, i] = st.u, st.lumped
        self.h_min[k, i], self.solve_us[k, i] = st.h_min, st.qp_solve_us
        self.degraded[k, i], self.clipped[k, i] = degraded, bool(st.input_clipped)
        self.alarms[k, i] = int(st.alarms) & 0xFF
        self.qp_status[k, i] = STATUS_CODE[st.qp_status]
        self.qp_active[k, i] = min(max(int(st.qp_active), 0), MAX_COUNT)
        self.qp_kinds[k, i] = int(st.qp_kinds) & 0xFF
        self.clf_slack[k, i], self.qp_relax[k, i] = st.qp_slack, st.qp_relax
        self.u_nom[k, i], self.u_corr[k, i] = st.u_nom, st.correction
        self.have_status[k, i] = True
        self.last_status[st.id] = st
        return True

    def finalize(self) -> None:
        """Decode whatever the channels still hold (end of the run, before the
        subscribers are undeclared)."""
        self.drain()

    def nbytes(self) -> int:
        """Bytes held by the preallocated arrays."""
        return sum(a.nbytes for a in vars(self).values() if isinstance(a, np.ndarray))
