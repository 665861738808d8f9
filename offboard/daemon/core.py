"""The per-agent offboard daemon: MAVLink to its own vehicle, Zenoh to the swarm.

It drives the same :mod:`offboard.agent.factory` object the in-process runner drives, in the
same order (docs/architecture.md, "Lockstep, step by step"):

1. the vehicle's ODOMETRY stamped t_k tells the step k (the clock; a follower never
   uses the position in it);
2. get the sensor's inputs of step k (:mod:`offboard.daemon.sensing_source`: the simulator's
   ``Truth``, or with ``--sensing odometry`` every vehicle's own published odometry) and
   every live neighbour's post-update ``Estimate`` of step k-1 (skipped inside the
   scenario's communication outages, which are deterministic);
3. ``agent.step(...)`` -> SET_ATTITUDE_TARGET with ``time_boot_ms`` = t_k, then publish
   the estimate for t_{k+1} and a status record.

Start-up like a real offboard application: wait for the heartbeat (logging what it waits
for every few seconds), send its own HEARTBEAT at 1 Hz, wait for its swarm (every agent
heard from, :class:`offboard.daemon.mavlink.mode_requests.SwarmReady`; ``--solo`` skips it), stream
setpoints, switch to OFFBOARD, arm; commands are retried
without ever blocking the setpoint stream. Faults (docs/security.md, "Offboard daemon:
link hygiene and failsafes"): a setpoint is re-sent only while it answers the vehicle's
current step (lockstep) or for one control period (real time), so with no valid step the
stream stops and the vehicle's offboard-loss failsafe acts; in real time, truth more than
``RUNNER_LOST_PERIODS`` behind the vehicle's clock (runner or router lost) replaces the
agent's step by a brake-and-hold on the vehicle's own ODOMETRY, and ``loss_land_after`` s
after the last truth the daemon lands its vehicle on its slot of the coordinated landing
plan from its own ODOMETRY (:mod:`offboard.daemon.runner_loss`); after a failsafe HOLD the
daemon asks for OFFBOARD again (:mod:`offboard.daemon.mavlink.mode_requests`). A neighbour that
stays
silent for ``neighbour_timeout`` seconds is declared lost and no longer waited for
(its data is then predicted by the agent, then dropped); it rejoins when it speaks.
In real-time mode (``--realtime``) it still steps once per new ODOMETRY stamp, but uses
the latest truth and neighbour data it holds instead of waiting (stale neighbours are
predicted by the agent); vehicle-sim measures how late each answer is. A ground start in
real time with ``--manual-start`` holds the agent idle on its pad until the ground
station's take-off command (docs/lifecycle.md).
"""

from __future__ import annotations

import logging
import signal
import time
from typing import Any

import numpy as np

from offboard.agent.factory import (
    FollowerAgent,
    LeaderAgent,
    make_agent,
)
from offboard.agent.peers import peer_ids, ready_ids
from offboard.daemon.commands import TAKEOFF_LATE_S, TAKEOFF_LEAD_S, DaemonCommands
from offboard.daemon.config import DaemonConfig
from offboard.daemon.link_guard import PayloadGuard
from offboard.daemon.mavlink.link import VehicleLink, mavlink
from offboard.daemon.mavlink.mode_requests import ModeRequests, SwarmReady
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.nav_check import NavigationCheck
from offboard.daemon.runner_loss import RUNNER_LOST_PERIODS, LossFlight, RunnerLoss
from offboard.daemon.sensing_source import SwarmSensing
from offboard.daemon.stream import SetpointStream
from offboard.daemon.wire_convert import (
    estimate_to_wire,
    estimates_from_wire,
    measured_state,
    status_to_wire,
)
from offboard.daemon.zenoh.link import SwarmBus
from offboard.daemon.zenoh.shared_batch import SharedBatch
from offboard.daemon.zenoh.shared_subs import SharedSubscriptions
from offboard.estimation.bearing import Formation, formation_from_scenario
from swarm_common import px4, wire
from swarm_common.enums import SensingSource

log = logging.getLogger(__name__)

LOOP_STALL_S = 0.25  # s: a main-loop iteration this late is a fault of the daemon
RESEND_S = 0.05  # s: re-send the current setpoint this often (lockstep: a lost datagram)
# s: re-publish the last two estimates after this long without a new one (late joiners,
# lost datagrams), then after twice as long, up to REPUBLISH_MAX_S: a slow lockstep run
# (64 agents packed: 75-280 ms a step) otherwise republished every 0.1 s of every step and
# each peer decoded and guarded three times the estimates it needed. The cap stays well
# below the neighbour timeout (0.45 s), so a waiting peer still hears twice in it.
REPUBLISH_S = 0.1
REPUBLISH_MAX_S = 0.2
# s: the longest wait for the vehicle's next datagram; every timer above is a multiple of
# it, and the ODOMETRY that starts a step wakes the loop at once
WAIT_CAP_S = 0.01
# s: the same while the swarm is not ready (no step, no setpoint, no request: nothing to
# time finely); a few dozen waiting daemons on a few cores otherwise starve the simulator
IDLE_WAIT_S = 0.05
WAIT_LOG_S = 3.0  # s: start-up waits say what they wait for this often
__all__ = ["RUNNER_LOST_PERIODS", "TAKEOFF_LATE_S", "TAKEOFF_LEAD_S", "DaemonConfig",
           "OffboardDaemon"]


class OffboardDaemon(DaemonCommands, SetpointStream):
    """One agent's offboard process (ground-station commands: offboard.daemon.commands)."""

    def __init__(
        self, cfg: DaemonConfig, session: Any, form: Formation | None = None,
        shared: SharedSubscriptions | None = None, batch: SharedBatch | None = None,
    ) -> None:
        """``session``: an open Zenoh session (shared by the daemons of a packed process);
        ``form``: the scenario's formation when the caller already built it; ``shared``:
        the Zenoh subscriptions of a packed process's daemons
        (:mod:`offboard.daemon.zenoh.shared_subs`),
        None for subscribers of its own; ``batch``: their received estimates as one batch
        per step (:mod:`offboard.daemon.zenoh.shared_batch`, lockstep only), None for batches of its
        own."""
        self.cfg = cfg
        sc = cfg.scenario
        self.sc = sc
        self.id = cfg.agent_id
        form = formation_from_scenario(sc) if form is None else form
        self.others = peer_ids(form, cfg.agent_id)  # whose estimates it reads and awaits
        self._index_of = {aid: j for j, aid in enumerate(form.ids)}  # id -> scenario index
        self._peer_idx = np.array([self._index_of[j] for j in self.others], dtype=np.int64)
        self.shared_batch = batch if cfg.lockstep else None
        ready = [] if cfg.solo else ready_ids(form, cfg.agent_id)  # heard before flying
        self.agent = make_agent(sc, cfg.agent_id, method=cfg.method, seed=cfg.seed, form=form)
        self.control_hz = int(sc.run.control_hz)
        self.link = VehicleLink(cfg.mavlink_url, cfg.agent_id, self.control_hz, cfg.lockstep,
                                tlog=cfg.tlog, signing_key=cfg.signing_key,
                                trim_streams=not cfg.keep_streams)
        guard = PayloadGuard(list(sc.ids), list(sc.leader_ids), self.control_hz, cfg.agent_id)
        self.bus = SwarmBus(session, cfg.swarm, cfg.agent_id, guard,
                            odometry=cfg.sensing is SensingSource.ODOMETRY, peers=self.others,
                            ready=ready, shared=shared)
        self.lost: set[int] = set()
        self.extra_outages: list[tuple[float, float]] = []
        self.last_step = -1
        # (time_boot_ms, q_ned float32 (4,), normalised thrust float32)
        self.answer: tuple[int, np.ndarray, np.float32] | None = None
        self.answer_from_loss = False  # the answer is runner_loss's (valid while lost)
        self.answer_step = -1  # the vehicle step the answer is for
        self.answer_at = 0.0  # monotonic time it was computed
        self.vehicle_step = -1  # step of the vehicle's latest accepted ODOMETRY
        self.last_send = 0.0
        self.stream_since = 0.0  # start of the current gap-free setpoint stream
        self.streaming = False
        self.odo_pub_step = -1  # the last step whose own odometry went out
        self.keeper = OffboardKeeper(cfg.stream_before_offboard, cfg.manual_start)
        self.modes = ModeRequests(self.link, self.keeper, cfg.agent_id)
        self.loss = RunnerLoss(self.control_hz, cfg.loss_land_after)
        self.loss_flight = LossFlight(sc, self.agent.index, cfg.agent_id, self.loss)
        # real-time followers: the DESO estimate against the vehicle's own odometry
        follower = isinstance(self.agent, FollowerAgent)
        checked = follower and not cfg.lockstep and cfg.nav_gate_m > 0.0
        self.nav = NavigationCheck(self.control_hz, cfg.nav_gate_m) if checked else None
        self.ready = SwarmReady(cfg.agent_id, ready, cfg.solo, WAIT_LOG_S)
        self.sensing = SwarmSensing(
            cfg.sensing, list(sc.ids), cfg.agent_id, self.bus, self.loss,
            lockstep=cfg.lockstep, solo=cfg.solo, truth_timeout=cfg.truth_timeout,
            neighbour_timeout=cfg.neighbour_timeout, startup_timeout=cfg.heartbeat_timeout,
            sensing_range_m=sc.formation.sensing_range_m, stopped=lambda: self.stop,
            on_lost=lambda: self.keeper.fault(time.monotonic()),
        )
        self.last_estimate: wire.Estimate | None = None
        self.prev_estimate: wire.Estimate | None = None
        self.last_est_pub = 0.0
        self.republish_after = REPUBLISH_S  # s without a new estimate before re-sending
        self.stop = False
        self.trajectory_started = False
        self.land_at: float | None = cfg.land_at
        self.cooperative = True
        self.bad_commands = 0  # commands with unusable fields: counted, logged, dropped
        # CPU of this thread inside agent.step (s): the control law runs on the main thread
        # alone (numba kernels, single-threaded BLAS). Not the process's CPU clock: it
        # counted Zenoh's threads as control, and reading it sums every thread and locks
        # the run queue of each one running on another core (19 % of the wall-clock
        # samples of a busy packed process; docs/performance.md, seventh round)
        self.control_cpu_s = 0.0
        self.control_steps = 0
        if not cfg.lockstep and cfg.manual_start and self.agent.hold_for_takeoff():
            log.info("agent %d: on its pad until the take-off command", self.id)

    # -- helpers ----------------------------------------------------------------------
    def _zeta(self) -> np.ndarray | None:
        return self.agent.deso.zeta if isinstance(self.agent, FollowerAgent) else None

    def _publish_estimate(self, est: wire.Estimate) -> None:
        if self.last_estimate is not None and self.last_estimate.step != est.step:
            self.prev_estimate = self.last_estimate
        self.last_estimate = est
        self.last_est_pub = time.monotonic()
        self.republish_after = REPUBLISH_S
        self.bus.publish_estimate(est)

    def _republish_estimates(self) -> None:
        """Re-send the last two estimates: a neighbour still at step k needs ours of k-1
        (the next re-send backs off, :data:`REPUBLISH_MAX_S`)."""
        for est in (self.prev_estimate, self.last_estimate):
            if est is not None:
                self.bus.publish_estimate(est)
        self.last_est_pub = time.monotonic()
        self.republish_after = min(2.0 * self.republish_after, REPUBLISH_MAX_S)

    # -- the control step ---------------------------------------------------------------
    def _neighbours_for(self, k: int, t: float) -> tuple[dict[int, wire.Estimate], bool]:
        """Neighbour estimates of step k-1 (lockstep: wait for every live one)."""
        ok = self.comm_ok(t)
        if not ok:
            return {}, False
        if not self.cfg.lockstep:
            latest = dict(self.bus.latest_estimate)
            return latest, True
        want = [j for j in self.others if j not in self.lost]

        def have_all() -> bool:
            got = self.bus.estimates.get(k - 1, {})
            return all(j in got for j in want)

        # Step 0 waits for every agent's initial estimate as long as start-up may take
        # (the others may still be importing); later a silent neighbour is declared lost.
        # (--solo: no start-up wait for neighbours that may never come)
        startup = k == 0 and not self.cfg.solo
        timeout = self.cfg.heartbeat_timeout if startup else self.cfg.neighbour_timeout
        complete = self.bus.wait(lambda: self.stop or have_all(), timeout) and not self.stop
        got = self.bus.estimates_at(k - 1)
        if not complete:
            for j in want:
                if j not in got:
                    log.warning("agent %d: neighbour %d silent at step %d: lost", self.id, j, k)
                    self.lost.add(j)
        for j in list(self.lost):
            if j in got:
                self.lost.discard(j)
                log.info("agent %d: neighbour %d back", self.id, j)
        return got, True

    def _loss_step(self, k: int, t: float, time_boot_ms: int) -> bool:
        """Runner or router lost (real time): the setpoint of offboard.daemon.runner_loss's
        LossFlight from the vehicle's own ODOMETRY (brake and hold, then the landing)."""
        if self.cfg.lockstep or not self.loss.lost:
            return False
        got = self._measured(0.0)
        sp = None if got is None else self.loss_flight.setpoint(t, *got)
        if got is None or sp is None:
            return False
        self.answer, self.answer_from_loss = (time_boot_ms, sp.q_ned, sp.thrust_norm), True
        self.answer_step, self.answer_at = k, time.monotonic()
        # the lost runner is a standing fault: a failsafe HOLD on the way down (a stalled
        # host) is taken back to OFFBOARD even when the vehicle's STATUSTEXT was missed
        self.keeper.fault(self.answer_at)
        self._send_answer()
        if self.loss_flight.disarm_due(t, float(got[0][2]), self.link.armed):
            self.modes.disarm()
        return True

    def _measured(self, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The vehicle's (position, velocity) ENU from its latest ODOMETRY, the position
        carried ``dt`` s ahead (offboard.daemon.wire_convert.measured_state); None without one."""
        odo = self.link.odometry
        return None if odo is None else measured_state(odo, dt)

    def _check_navigation(self, k: int, t: float) -> None:
        """A real-time follower's estimate ẑ₁ (valid a period ahead) against its vehicle's
        ODOMETRY predicted as far (offboard.daemon.nav_check): once diverged, the runner-loss hold
        and landing on odometry from the next step on, for good."""
        if self.nav is None or not isinstance(self.agent, FollowerAgent) or not self.nav.due(k):
            return
        got = self._measured(1.0 / self.control_hz)
        if got is not None and self.nav.update(k, self.agent.deso.z1, got[0]):
            self.loss.navigation_fault(t)
            self.keeper.fault(time.monotonic())
            t_land = self.loss.t_land
            log.error("agent %d: estimate off its odometry by more than %g m at t=%.2f s: "
                      "holding on odometry; %s", self.id, self.nav.gate_m, t,
                      "no landing (--loss-land-after 0)" if t_land is None
                      else f"landing at t={t_land:.2f} s")

    def control_step(self, k: int, t: float, time_boot_ms: int) -> bool:
        sensed = self.sensing.for_step(k)
        if sensed is None:
            return False
        self._apply_commands(t)
        self._maybe_start_landing(t)
        if not self.cfg.lockstep and isinstance(self.agent, LeaderAgent):
            self._maybe_start_trajectory(t)
        received, comm_ok = self._neighbours_for(k, t)
        neighbours = (
            estimates_from_wire(self._index_of, len(self._index_of), received)
            if self.shared_batch is None
            else self.shared_batch.batch_for(k - 1, received, self._peer_idx)
        )
        cpu0 = time.thread_time()
        out = self.agent.step(k, t, sensed[0], sensed[1], neighbours, comm_ok)
        self.control_cpu_s += time.thread_time() - cpu0
        self.control_steps += 1
        self._check_navigation(k, t)
        self.answer, self.answer_from_loss = (time_boot_ms, out.q_ned, out.thrust_norm), False
        self.answer_step, self.answer_at = k, time.monotonic()
        self._send_answer()
        est = estimate_to_wire(out.estimate, k, self._zeta())
        self._publish_estimate(self._mark_cooperation(est, t))
        mode = px4.short_name(self.link.custom_mode)
        self.bus.publish_status(status_to_wire(self.id, k, t, out, mode, comm_ok))
        return True

    def _mark_cooperation(self, est: wire.Estimate, t: float) -> wire.Estimate:
        """Out of OFFBOARD after the mission had it there (a third party's AUTO.LAND, HOLD,
        ...): the agent's setpoints no longer fly, so publish cooperative=False and the
        vehicle's measured state instead of the estimate of a controller that does not fly
        it (docs/lifecycle.md, "Third-party AUTO.LAND"). Control is not taken back."""
        # the mission has had the vehicle in OFFBOARD: latched by the link, backlog included
        cooperative = self.link.in_offboard or not self.link.offboard_reported
        if cooperative != self.cooperative:
            self.cooperative = cooperative
            mode = px4.short_name(self.link.custom_mode)
            if cooperative:
                log.info("agent %d: vehicle back in OFFBOARD at t=%.2f s", self.id, t)
            else:
                log.warning("agent %d: vehicle left OFFBOARD (%s) at t=%.2f s: publishing "
                            "its measured state as non-cooperative", self.id, mode, t)
        if cooperative:
            return est
        est.cooperative = False
        got = self._measured(1.0 / self.control_hz)
        if got is not None:
            est.z1, est.z2 = got
            est.z3 = np.zeros(3)
        return est

    # -- main loop ----------------------------------------------------------------------
    def _vehicle_clock(self) -> None:
        """The vehicle's step from its latest ODOMETRY: the reference of the Zenoh guard."""
        odo = self.link.odometry
        k = -1 if odo is None else int(round(odo.time_usec * 1e-6 * self.control_hz))
        if k != self.vehicle_step and k >= 0:
            self.vehicle_step = k
            self.bus.set_reference(k)

    def _publish_odometry(self, k: int) -> None:
        """Our vehicle's measured state at t_k on Zenoh, once per step (the others'
        ``--sensing odometry``), and handed to our own sensing source."""
        if self.cfg.sensing is SensingSource.TRUTH and not self.bus.odometry_matched:
            return  # nobody reads it: neither our sensing (truth) nor a subscriber
        got = None if k == self.odo_pub_step else self._measured(0.0)
        if got is None:
            return
        self.odo_pub_step = k
        msg = wire.Odometry(self.id, k, k / self.control_hz, wire.f32(got[0]), wire.f32(got[1]))
        self.sensing.set_own(msg)
        self.bus.publish_odometry(msg)

    def _on_odometry(self) -> None:
        """One control step per new ODOMETRY stamp (both modes), once the swarm is ready
        (the arming policy: no setpoint, so no OFFBOARD or arm, before)."""
        k = self.vehicle_step
        if k >= 0:
            self._publish_odometry(k)
        if k > self.last_step and self.ready.check(self.bus.heard, time.monotonic()):
            self.bus.end_readiness()
            t = k / self.control_hz
            ms = int(round(t * 1000))
            if self.control_step(k, t, ms) or self._loss_step(k, t, ms):
                self.last_step = k

    def run(self) -> int:
        """The whole life of a daemon alone in its process (``offboard --agent``)."""
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        try:
            rc = self.start()
            if rc is not None:
                return rc
            last_iter = time.monotonic()
            while not self.stop:
                rc = self.iterate(last_iter, WAIT_CAP_S if self.ready.ready else IDLE_WAIT_S)
                if rc is not None:
                    return rc
                last_iter = time.monotonic()  # between iterations: not our own waits
            self.say_stopped()
            return 0
        finally:
            self.close()

    def start(self) -> int | None:
        """Wait for the vehicle's heartbeat (the link lock), ask for its HEARTBEAT rate and
        publish the initial estimate; None when the main loop may begin, else the exit
        status (0 when stopped meanwhile, 2 when no vehicle answered)."""
        cfg = self.cfg
        if not self.link.wait_lock(cfg.heartbeat_timeout, lambda: self.stop, WAIT_LOG_S):
            if not self.stop:
                log.error("agent %d: no heartbeat from vehicle on %s", self.id, cfg.mavlink_url)
            return 0 if self.stop else 2
        log.info("agent %d: vehicle heartbeat received (%s)", self.id, cfg.mavlink_url)
        self.link.commands.message_interval(
            mavlink.MAVLINK_MSG_ID_HEARTBEAT, cfg.heartbeat_interval
        )
        if isinstance(self.agent, FollowerAgent):
            for line in self.agent.gains.lines():
                log.info("agent %d: %s", self.id, line)
        self._publish_estimate(estimate_to_wire(self.agent.initial_estimate(), -1, self._zeta()))
        return None

    def iterate(self, last_iter: float, poll_s: float = 0.0) -> int | None:
        """One pass of the main loop: read the vehicle (waiting up to ``poll_s`` for a
        datagram; ODOMETRY wakes it at once), pump Zenoh, step on a new ODOMETRY stamp,
        keep the setpoint stream, estimates and commands going. ``last_iter``: the end of
        the previous pass of this process's loop (a later start is a stall). None while
        running, else the exit status (3: vehicle heartbeat lost)."""
        cfg = self.cfg
        now = time.monotonic()
        if now - last_iter > LOOP_STALL_S:  # stopped, swapped out: the stream had a gap
            self.keeper.fault(now)
            self.streaming = False  # the vehicle must see the stream again first
            log.warning("agent %d: main loop stalled %.2f s", self.id, now - last_iter)
        self.link.poll(poll_s)
        self.link.send_heartbeat()
        self._vehicle_clock()
        self.bus.pump(with_shared=False)  # a packed process's host pumps those once a pass
        now = time.monotonic()
        if now - self.link.heartbeat_time > cfg.vehicle_lost_timeout:
            log.error("agent %d: vehicle heartbeat lost", self.id)
            return 3
        self._on_odometry()
        now = time.monotonic()
        if self.answer is not None and now - self.last_send > RESEND_S:
            self._send_answer()  # lockstep: the vehicle may have missed it
        self._check_stream(now)
        if (self.last_estimate is not None and now - self.last_est_pub > self.republish_after
                and not self.loss.landing):
            self._republish_estimates()  # for late joiners / lost datagrams
        if self.link.commands:
            done, res = self.link.commands.finished(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)
            if done and res != mavlink.MAV_RESULT_ACCEPTED:  # its default (1 Hz) still works
                log.warning("agent %d: HEARTBEAT interval %.2f s not accepted (result %s)",
                            self.id, cfg.heartbeat_interval, res)
        streaming_s = now - self.stream_since if self.streaming else 0.0
        self.modes.request(now, self.answer is not None, streaming_s)
        self.link.commands.tick()
        return None

    def say_stopped(self) -> None:
        """The last line: drops, and the CPU the control law took (bench_distributed reads
        it to tell the control from the plumbing)."""
        nav = ("" if self.nav is None
               else f"; estimate at most {self.nav.worst_m:.3f} m from odometry (after grace)")
        log.info("agent %d: stopped; dropped MAVLink %s, Zenoh %s; control CPU %.3f s over "
                 "%d steps; truth lag at most %d periods%s", self.id, self.link.drops.counts,
                 self.bus.drops.counts, self.control_cpu_s, self.control_steps,
                 self.loss.max_lag, nav)

    def close(self) -> None:
        self.link.close()
        self.bus.close()

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop = True
