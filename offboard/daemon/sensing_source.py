"""Where a daemon's sensor inputs come from: the (N,3) ENU positions and velocities that
:class:`offboard.estimation.sensing.Sensor` turns into relative measurements
(docs/px4/offboard-component.md,
"Sensing sources").

* ``truth`` (default): the simulator's ``Truth`` of step k (lockstep: waited for; real
  time: the latest one unless it is more than ``RUNNER_LOST_PERIODS`` behind the vehicle's
  clock, when the runner or router counts as lost, :mod:`offboard.daemon.runner_loss`). Keeps the
  in-process runner's bit-for-bit equality.
* ``odometry``: no simulator truth at all. Row i is the agent's own vehicle's ODOMETRY at
  t_k (converted once through :mod:`swarm_common.frames`, published by the daemon as
  ``wire.Odometry``); row j is what agent j's daemon published for its vehicle. Lockstep:
  waits for every live neighbour's odometry of step k (a neighbour silent for
  ``neighbour_timeout`` is lost and no longer awaited until it speaks again); real time:
  the latest one. A neighbour whose latest odometry is more than ``RUNNER_LOST_PERIODS``
  steps old (or never heard) is put out of sensing range: the sensor then reports no
  measurement of it, exactly like a dropout. With no neighbour odometry newer than that
  (real time), the router counts as lost, the same rule as for truth.

The choice is a :class:`SensingSource` (``--sensing``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from offboard.daemon.runner_loss import RUNNER_LOST_PERIODS, RunnerLoss
from offboard.daemon.zenoh.link import SwarmBus
from swarm_common import wire
from swarm_common.enums import SensingSource

log = logging.getLogger(__name__)

OWN_REPUT_S = 0.2  # s: lockstep, waiting for the others' odometry: our own is put again

WAIT_LOG_S = 3.0  # s: how often a start-up wait says what it waits for
FAR_FACTOR = 10.0  # an unseen neighbour's row: this many sensing ranges away (not sensed)


class SwarmSensing:
    """The sensor inputs of one agent for step k, from ``source``."""

    def __init__(
        self, source: SensingSource, ids: list[int], agent_id: int, bus: SwarmBus,
        loss: RunnerLoss, *, lockstep: bool, solo: bool, truth_timeout: float,
        neighbour_timeout: float, startup_timeout: float, sensing_range_m: float,
        stopped: Callable[[], bool], on_lost: Callable[[], None],
    ) -> None:
        """``on_lost``: called when the runner or router becomes lost (real time)."""
        self.source = source
        self.ids = list(ids)
        self.id = agent_id
        self.bus = bus
        self.loss = loss
        self.lockstep = lockstep
        self.solo = solo
        self.truth_timeout = truth_timeout
        self.neighbour_timeout = neighbour_timeout
        self.startup_timeout = startup_timeout
        self.far = FAR_FACTOR * max(float(sensing_range_m), 1.0)
        self.stopped = stopped
        self.on_lost = on_lost
        self.own: wire.Odometry | None = None
        self.own_put_at = 0.0  # monotonic s of the last put of ``own``
        self.silent: set[int] = set()  # odometry senders declared silent (not awaited)
        self.said_waiting = 0.0

    def set_own(self, odo: wire.Odometry) -> None:
        """The agent's own vehicle's odometry of the step about to run (published by the
        daemon before it waits for the others')."""
        self.own = odo
        self.own_put_at = time.monotonic()

    def put_own_again(self) -> None:
        """Put our own odometry of step k again every ``OWN_REPUT_S`` for as long as k is
        our latest step: while we wait for the others' odometry of k, and while our vehicle
        waits (lockstep) for a peer that is still at k. A put made before a peer's
        subscription reached us is lost (Zenoh keeps no history), and that peer, waiting
        for it, would otherwise sit out the whole start-up timeout at step 0 (seen on a
        loaded host: 30 s, after which it flew its first steps without a neighbour; in CI
        the peer had already sent its step-0 setpoint and stopped re-putting while it was
        waiting for the vehicle). Receivers store by (step, id), so a repeat changes
        nothing."""
        now = time.monotonic()
        if self.own is not None and now - self.own_put_at >= OWN_REPUT_S:
            self.own_put_at = now
            self.bus.publish_odometry(self.own)

    def for_step(self, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(p, v), (N,3) ENU in scenario order, for step k; None: no usable data (lockstep:
        nothing in time; real time: runner/router lost, or no own odometry)."""
        if self.source is SensingSource.TRUTH:
            truth = self._truth_for(k)
            return None if truth is None else (truth.p, truth.v)
        return self._odometry_for(k)

    # -- truth ---------------------------------------------------------------------------
    def _truth_for(self, k: int) -> wire.Truth | None:
        """Lockstep: the truth of step k, waited for; real time: the latest one unless the
        runner or router is lost (then None)."""
        bus = self.bus
        if self.lockstep:
            if not bus.wait(lambda: self.stopped() or k in bus.truth, self.truth_timeout):
                log.warning("agent %d: no truth for step %d", self.id, k)
                return None
            return bus.truth.get(k)
        truth = bus.latest_truth
        if truth is None:
            self._say_waiting("truth")
        ok = self._observe(k, None if truth is None else truth.step, "truth")
        return truth if ok else None

    # -- odometry ------------------------------------------------------------------------
    def _odometry_for(self, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        own = self.own
        if own is None or own.step != k:
            return None
        others = [j for j in self.ids if j != self.id]
        bus = self.bus
        if self.lockstep:
            want = [j for j in others if j not in self.silent]

            def have_all() -> bool:
                self.put_own_again()
                got = bus.odometry.get(k, {})
                return all(j in got for j in want)

            timeout = self.startup_timeout if k == 0 and not self.solo else self.neighbour_timeout
            complete = bus.wait(lambda: self.stopped() or have_all(), timeout)
            got = bus.odometry.get(k, {})
            if not complete and not self.stopped():
                for j in want:
                    if j not in got:
                        log.warning("agent %d: no odometry of %d at step %d: not awaited "
                                    "until it speaks", self.id, j, k)
                        self.silent.add(j)
            for j in [j for j in self.silent if j in got]:
                self.silent.discard(j)
                log.info("agent %d: odometry of %d back", self.id, j)
        else:
            newest = max((o.step for o in bus.latest_odometry.values()), default=None)
            if newest is None and others and not self.solo:
                self._say_waiting("the neighbours' odometry")
            ref = k if self.solo or not others else newest
            if not self._observe(k, ref, "neighbour odometry"):
                return None
        return self.arrays(k, own, bus.odometry.get(k, {}), bus.latest_odometry)

    def arrays(
        self, k: int, own: wire.Odometry, at_k: dict[int, wire.Odometry],
        latest: dict[int, wire.Odometry],
    ) -> tuple[np.ndarray, np.ndarray]:
        """(p, v) (N,3): own row, each neighbour's odometry of step k, else its latest one
        at most RUNNER_LOST_PERIODS steps old, else a row out of sensing range at rest."""
        n = len(self.ids)
        p = np.zeros((n, 3))
        v = np.zeros((n, 3))
        for row, j in enumerate(self.ids):
            odo = own if j == self.id else at_k.get(j) or latest.get(j)
            if odo is not None and 0 <= k - odo.step <= RUNNER_LOST_PERIODS:
                p[row], v[row] = odo.p, odo.v
            else:  # not seen: far away along +x (the sensor reports it out of range)
                p[row] = own.p + np.array([self.far * (row + 1), 0.0, 0.0])
        return p, v

    # -- shared --------------------------------------------------------------------------
    def _observe(self, k: int, ref_step: int | None, what: str) -> bool:
        """Real time: feed the runner-loss detector with the newest step of ``what``;
        True while it is neither stalled nor lost (a stall is logged by LossFlight)."""
        change = self.loss.observe(k, ref_step)
        if change == "lost":
            self.on_lost()
            t_land = self.loss.t_land
            log.error("agent %d: %s lost at step %d (runner or router gone?): holding on "
                      "odometry; %s", self.id, what, k,
                      "no landing (--loss-land-after 0)" if t_land is None
                      else f"landing at t={t_land:.2f} s unless {what} is back first")
        elif change == "back":
            log.info("agent %d: %s back at step %d", self.id, what, k)
        return not self.loss.lost

    def _say_waiting(self, what: str) -> None:
        now = time.monotonic()
        if now - self.said_waiting >= WAIT_LOG_S:
            self.said_waiting = now
            log.info("agent %d: waiting for %s on Zenoh", self.id, what)
