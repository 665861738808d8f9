"""The per-agent offboard daemon: MAVLink to its own vehicle, Zenoh to the swarm.

:class:`OffboardDaemon` is the process around one agent: it opens both links, builds the
agent loop (:mod:`offboard.daemon.loop`: the agent's step, what it publishes, what it
sends the vehicle) on them, with the driver of its clock (:mod:`offboard.daemon.drivers`:
lockstep or real time), and keeps the links' life and the vehicle's modes going.

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
station's take-off command (docs/lifecycle.md). A follower's filter keeps the fence its
vehicle stores, downloaded whenever a ground station uploads another
(:mod:`offboard.daemon.fence_sync`, docs/world.md).
"""

from __future__ import annotations

import logging
import signal
import time
from typing import Any

from offboard.agent.factory import FollowerAgent, make_agent
from offboard.agent.peers import peer_ids, ready_ids
from offboard.daemon.commands import TAKEOFF_LATE_S, TAKEOFF_LEAD_S, GroundCommands
from offboard.daemon.config import DaemonConfig
from offboard.daemon.drivers import LockstepDriver, RealtimeDriver, StepDriver
from offboard.daemon.fence_sync import FenceSync
from offboard.daemon.link_guard import PayloadGuard
from offboard.daemon.loop import AgentLoop
from offboard.daemon.mavlink.link import VehicleLink, mavlink
from offboard.daemon.mavlink.mode_requests import ModeRequests, SwarmReady
from offboard.daemon.mavlink.offboard_keeper import OffboardKeeper
from offboard.daemon.runner_loss import RUNNER_LOST_PERIODS, RunnerLoss
from offboard.daemon.sensing_source import SwarmSensing
from offboard.daemon.stream import EstimateOutbox, SetpointStream
from offboard.daemon.zenoh.link import SwarmBus
from offboard.daemon.zenoh.shared_batch import SharedBatch
from offboard.daemon.zenoh.shared_subs import SharedSubscriptions
from offboard.estimation.bearing import Formation, formation_from_scenario
from swarm_common.enums import SensingSource

log = logging.getLogger(__name__)

LOOP_STALL_S = 0.25  # s: a main-loop iteration this late is a fault of the daemon
RESEND_S = 0.05  # s: re-send the current setpoint this often (lockstep: a lost datagram)
# s: the longest wait for the vehicle's next datagram; every timer of the loop is a
# multiple of it, and the ODOMETRY that starts a step wakes the loop at once
WAIT_CAP_S = 0.01
# s: the same while the swarm is not ready (no step, no setpoint, no request: nothing to
# time finely); a few dozen waiting daemons on a few cores otherwise starve the simulator
IDLE_WAIT_S = 0.05
WAIT_LOG_S = 3.0  # s: start-up waits say what they wait for this often
__all__ = ["RUNNER_LOST_PERIODS", "TAKEOFF_LATE_S", "TAKEOFF_LEAD_S", "DaemonConfig",
           "OffboardDaemon"]


class OffboardDaemon:
    """One agent's offboard process. Its parts: ``link`` and ``bus`` (the transport to its
    vehicle and to the swarm), ``keeper`` and ``modes`` (the vehicle's OFFBOARD and arming
    requests), ``loss`` (the runner-loss state), ``loop`` (the agent loop, with its
    ``driver``, ``commands``, ``stream`` and ``outbox``)."""

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
        self.id = cfg.agent_id
        self.stop = False
        form = formation_from_scenario(sc) if form is None else form
        others = peer_ids(form, cfg.agent_id)  # whose estimates it reads and awaits
        index_of = {aid: j for j, aid in enumerate(form.ids)}  # id -> scenario index
        ready = [] if cfg.solo else ready_ids(form, cfg.agent_id)  # heard before flying
        agent = make_agent(sc, cfg.agent_id, method=cfg.method, seed=cfg.seed, form=form)
        control_hz = int(sc.run.control_hz)
        # the follower's filter keeps the fence its vehicle stores (docs/world.md)
        self.fence = (FenceSync(cfg.agent_id, sc.world.geofence, sc.controller.d_safe_m,
                                agent.replace_fence)
                      if isinstance(agent, FollowerAgent) else None)
        # the transport
        self.link = VehicleLink(cfg.mavlink_url, cfg.agent_id, control_hz, cfg.lockstep,
                                tlog=cfg.tlog, signing_key=cfg.signing_key,
                                trim_streams=not cfg.keep_streams)
        guard = PayloadGuard(list(sc.ids), list(sc.leader_ids), control_hz, cfg.agent_id)
        self.bus = SwarmBus(session, cfg.swarm, cfg.agent_id, guard,
                            odometry=cfg.sensing is SensingSource.ODOMETRY, peers=others,
                            ready=ready, shared=shared)
        # the vehicle's modes and the runner-loss state
        self.keeper = OffboardKeeper(cfg.stream_before_offboard, cfg.manual_start)
        self.modes = ModeRequests(self.link, self.keeper, cfg.agent_id)
        self.loss = RunnerLoss(control_hz, cfg.loss_land_after)
        # the agent loop and its driver
        driver: StepDriver
        if cfg.lockstep:
            driver = LockstepDriver(
                self.bus, cfg.agent_id, others, index_of, batch, solo=cfg.solo,
                startup_timeout=cfg.heartbeat_timeout, neighbour_timeout=cfg.neighbour_timeout,
                stopped=lambda: self.stop)
        else:
            driver = RealtimeDriver(
                sc, agent, cfg.agent_id, self.link, self.bus, index_of, keeper=self.keeper,
                modes=self.modes, loss=self.loss, nav_gate_m=cfg.nav_gate_m,
                manual_start=cfg.manual_start)
        sensing = SwarmSensing(
            cfg.sensing, list(sc.ids), cfg.agent_id, self.bus, self.loss,
            lockstep=cfg.lockstep, solo=cfg.solo, truth_timeout=cfg.truth_timeout,
            neighbour_timeout=cfg.neighbour_timeout, startup_timeout=cfg.heartbeat_timeout,
            sensing_range_m=sc.formation.sensing_range_m, stopped=lambda: self.stop,
            on_lost=lambda: self.keeper.fault(time.monotonic()),
        )
        stream = SetpointStream(cfg.agent_id, self.link, self.keeper, self.loss,
                                driver.answer_fresh)
        self.loop = AgentLoop(
            cfg.agent_id, agent, control_hz, self.link, self.bus, source=cfg.sensing,
            sensing=sensing, commands=GroundCommands(sc, agent, cfg.agent_id, cfg.land_at),
            stream=stream, outbox=EstimateOutbox(self.bus),
            ready=SwarmReady(cfg.agent_id, ready, cfg.solo, WAIT_LOG_S), driver=driver,
        )
        if self.fence is not None:  # the filter and the simulator disagree: every step says so
            self.loop.daemon_alarms = self.fence.alarm_bits

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
                poll_s = WAIT_CAP_S if self.loop.ready.ready else IDLE_WAIT_S
                rc = self.iterate(last_iter, poll_s)
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
        agent = self.loop.agent
        if isinstance(agent, FollowerAgent):
            # an UNSTABLE report is never INFO: an error, a warning with --allow-infeasible
            level = (logging.INFO if agent.gains.ok else
                     logging.WARNING if self.cfg.scenario.allow_infeasible else logging.ERROR)
            for line in agent.gains.lines():
                log.log(level, "agent %d: %s", self.id, line)
        self.loop.publish_initial_estimate()
        return None

    def iterate(self, last_iter: float, poll_s: float = 0.0) -> int | None:
        """One pass of the main loop: read the vehicle (waiting up to ``poll_s`` for a
        datagram; ODOMETRY wakes it at once), pump Zenoh, step on a new ODOMETRY stamp,
        keep the setpoint stream, estimates and commands going. ``last_iter``: the end of
        the previous pass of this process's loop (a later start is a stall). None while
        running, else the exit status (3: vehicle heartbeat lost)."""
        cfg = self.cfg
        stream = self.loop.stream
        now = time.monotonic()
        if now - last_iter > LOOP_STALL_S:  # stopped, swapped out: the stream had a gap
            stream.gap(now)  # the vehicle must see the stream again first
            log.warning("agent %d: main loop stalled %.2f s", self.id, now - last_iter)
        self.link.poll(poll_s)
        self.follow_fence(time.monotonic())
        self.link.send_heartbeat()
        self.loop.vehicle_clock()
        self.bus.pump(with_shared=False)  # a packed process's host pumps those once a pass
        now = time.monotonic()
        if now - self.link.heartbeat_time > cfg.vehicle_lost_timeout:
            log.error("agent %d: vehicle heartbeat lost", self.id)
            return 3
        self.loop.on_odometry()
        now = time.monotonic()
        if stream.answer is not None and now - stream.last_send > RESEND_S:
            stream.send()  # lockstep: the vehicle may have missed it
        stream.check(now)
        if self.loop.outbox.republish_due(now) and not self.loss.landing:
            self.loop.outbox.republish()  # for late joiners / lost datagrams
        if self.link.commands:
            done, res = self.link.commands.finished(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)
            if done and res != mavlink.MAV_RESULT_ACCEPTED:  # its default (1 Hz) still works
                log.warning("agent %d: HEARTBEAT interval %.2f s not accepted (result %s)",
                            self.id, cfg.heartbeat_interval, res)
        self.modes.request(now, stream.answer is not None, stream.streaming_s(now))
        self.link.commands.tick()
        return None

    def follow_fence(self, now: float) -> None:
        """The fence download's next request, and a finished download to the follower's
        filter (offboard.daemon.fence_sync): here, between two steps, so a step never sees
        half a swap."""
        self.link.fence.tick(now)
        got = self.link.fence.take()
        if self.fence is None:
            return
        if got is not None:
            self.fence.on_download(got, now)
        self.fence.on_origin(self.link.origin, now)

    def say_stopped(self) -> None:
        """The last line: drops, and the CPU the control law took (bench_distributed reads
        it to tell the control from the plumbing)."""
        loop = self.loop
        log.info("agent %d: stopped; dropped MAVLink %s, Zenoh %s; control CPU %.3f s over "
                 "%d steps; truth lag at most %d periods%s", self.id, self.link.drops.counts,
                 self.bus.drops.counts, loop.control_cpu_s, loop.control_steps,
                 self.loss.max_lag, loop.driver.summary())
        fence = "" if self.fence is None else self.fence.summary()
        if fence:
            log.info("agent %d: %s", self.id, fence)

    def close(self) -> None:
        self.link.close()
        self.bus.close()

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop = True
