"""The ``vehicle-sim`` process: dynamics + N vehicles + clock + Zenoh truth, one select loop.

Per control step k (t_k = k / control_hz), in both clock modes:

1. every vehicle updates its state machine (offboard loss, auto-disarm) and gives its
   attitude/thrust command; the dynamics integrate physics_hz / control_hz steps;
2. ``wire.Truth`` of the new step is published on ``wire.key_truth(swarm)``;
3. lockstep: every vehicle's ODOMETRY stamped t_k is sent; then the loop waits for the
   answers (SET_ATTITUDE_TARGET with ``time_boot_ms == round(t_k·1000)``) of every active
   vehicle, or ``step_timeout`` wall seconds. Real time: the loop waits for the wall clock.

Telemetry streams (HEARTBEAT 1 Hz etc.) run on the wall clock in both modes, per peer
(:mod:`vehicle_sim.autopilot.streams`), to the default remotes and the peers that spoke within
``mavlink_link.PEER_TIMEOUT_S``. With ``--signing-key`` every link verifies signatures and
every frame sent is signed; rejected frames are reported by a STATUSTEXT at most every
``REJECT_REPORT_S`` per vehicle, and in the stats (docs/security.md).
"""

from __future__ import annotations

import logging
import math
import selectors
import sys
import time

import numpy as np
from pymavlink.dialects.v20 import common as M

from swarm_common import frames, signing, wire
from swarm_common.ports import vehicle_ports
from swarm_common.scenario.model import Scenario
from vehicle_sim import stats
from vehicle_sim.autopilot.config import AutopilotConfig
from vehicle_sim.clock import LockstepClock, RealTimeClock
from vehicle_sim.link.endpoint import MavlinkLink
from vehicle_sim.link.server_io import ServerIO
from vehicle_sim.link.truth import TruthPublisher
from vehicle_sim.options import SimOptions, restrict
from vehicle_sim.physics.dynamics import SwarmDynamics
from vehicle_sim.services.geofence import scenario_fence_items
from vehicle_sim.vehicle import MSG_ODOMETRY, Vehicle

log = logging.getLogger(__name__)

LOCKSTEP_SUSPEND_AFTER = 5  # consecutive step timeouts before we stop waiting for a vehicle
LOCKSTEP_RESEND_S = 0.1  # re-send ODOMETRY t_k to a vehicle that has not answered yet
LOCKSTEP_SCAN_S = 0.005  # lockstep: telemetry streams scanned at most this often (s)
LINK_NAMES = ("api", "gcs")  # a vehicle's links; link i signs with signing link id i


def load_kernels(sc: Scenario) -> None:
    """Load the compiled kernels the simulator runs (swarm_common.jit) before its first
    step: a control period's physics of a throwaway swarm (as :meth:`SimServer.integrate`
    runs it), the setpoint decode and the telemetry's attitude conversions, so the first
    real step does not pay for loading (or, on a machine's first run, compiling) them."""
    warm = SwarmDynamics(sc, held=False)
    warm.advance_period(sc.substeps_per_control)  # the pair distances too (none for one)
    warm.lumped_accel()
    frames.euler_enu_from_quat_ned(np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32))
    frames.odometry_ned(warm.p[0], warm.v[0], warm.att[0])  # ODOMETRY
    frames.lag_rates_frd(warm.att[0], warm.cmd_att[0], warm.tau)
    frames.quat_from_rotm(frames.rotm_from_euler(0.0, 0.0, 0.0))  # mission items
    frames.quat_ned_from_euler_enu(0.0, 0.0, 0.0)  # attitude streams


def _still_to_answer(v: Vehicle, ms: int) -> bool:
    """Lockstep: the server waits for ``v``'s answer to the step stamped ``ms``."""
    return v.lockstep_should_wait() and v.answered_ms != ms


class SimServer(ServerIO):
    def __init__(self, sc: Scenario, opts: SimOptions) -> None:
        self.opts = opts
        self.sc = restrict(sc, opts.vehicles)
        self.dyn = SwarmDynamics(self.sc, seed=opts.seed, held=True)
        load_kernels(self.sc)
        self.substeps = self.sc.substeps_per_control
        self.dt = self.sc.control_dt
        if opts.lockstep:
            self.clock: LockstepClock | RealTimeClock = LockstepClock(self.dt, opts.step_timeout)
        else:
            self.clock = RealTimeClock(self.dt)
        self.stop_requested = False
        self.lockstep_timeouts = 0
        self.handler_errors = 0
        self.truth_pub = TruthPublisher()
        self.links: list[MavlinkLink] = []
        self.vehicles: list[Vehicle] = []
        self.vehicle_by_id: dict[int, Vehicle] = {}
        self.vlinks: dict[int, dict[str, MavlinkLink]] = {}
        self.forwarded: dict[tuple[int, int], float] = {}  # (vehicle, component) -> last
        self.sel = selectors.DefaultSelector()
        self._collisions_seen = 0
        self._min_dist = self.dyn.min_pair_distance() if self.dyn.n >= 2 else float("inf")
        self._last_resend: dict[int, float] = {}
        self.touched: set[int] = set()
        # lockstep: the vehicles still to answer this step as of the last full scan (None:
        # scan at the next poll), and the monotonic time of that scan
        self._pending: set[int] | None = None
        self._last_full_scan = -math.inf
        self._prestart_next = 0.0
        self._last_scan = -math.inf  # monotonic time of the last telemetry scan (run)
        self._rejects_reported: dict[int, tuple[int, float]] = {}
        opened = False
        try:
            self._open_links()
            if opts.zenoh:
                self.log(self.truth_pub.open(opts))
            opened = True
        finally:  # a busy port or Zenoh failing: release what was opened, then raise
            if not opened:
                self.close()

    # -- setup ------------------------------------------------------------------------
    def _open_links(self) -> None:
        o = self.opts
        for idx, aid in enumerate(self.sc.ids):
            cfg = AutopilotConfig(
                offboard_timeout=o.offboard_timeout,
                failsafe=o.failsafe,
                odometry_hz=o.odometry_hz,
                lockstep=o.lockstep,
                port_offset=o.port_offset,
            )
            if o.home is not None:
                cfg.home_lat, cfg.home_lon, cfg.home_alt = o.home
            v = Vehicle(aid, idx, self.dyn, cfg)
            if self.sc.world.geofence is not None:  # listed and checked as the filter keeps it
                v.mission.preload_fence(scenario_fence_items(cfg, self.sc.world.geofence))
            if o.signing_key is not None:
                v.sign_links(o.signing_key, LINK_NAMES, signing.setup_signing)
            self.vehicles.append(v)
            self.vehicle_by_id[aid] = v
            ports = vehicle_ports(aid, o.port_offset)
            api = MavlinkLink(
                "api", aid, ports.api_local, (o.remote_host, ports.api_remote), o.bind_host,
                key=o.signing_key,
            )  # fmt: skip
            self.links.append(api)
            gcs = MavlinkLink(
                "gcs", aid, ports.gcs_local, (o.remote_host, ports.gcs_remote), o.bind_host,
                key=o.signing_key, unsigned_ok=o.unsigned_gcs,
            )  # fmt: skip
            self.links.append(gcs)
            self.vlinks[aid] = {"api": api, "gcs": gcs}
            self.sel.register(api.sock, selectors.EVENT_READ, (v, api))
            self.sel.register(gcs.sock, selectors.EVENT_READ, (v, gcs))

    def log(self, text: str, level: int = logging.INFO) -> None:
        """A diagnostic line stamped with the simulation time."""
        if log.isEnabledFor(level):
            log.log(level, "t=%.2f %s", self.clock.t(), text)

    def close(self) -> None:
        """Close sockets and Zenoh; safe to call twice."""
        for link in self.links:
            try:
                self.sel.unregister(link.sock)
            except (KeyError, ValueError, OSError) as exc:
                log.debug("unregister %s link: %r", link.name, exc)
            link.close()
        self.links = []
        try:
            self.sel.close()
        except OSError as exc:
            log.debug("selector close: %r", exc)
        self.truth_pub.close()

    # -- per step ---------------------------------------------------------------------
    def truth(self) -> wire.Truth:
        d = self.dyn
        return wire.Truth(
            step=self.clock.k,
            t=self.clock.t(),
            ids=list(self.sc.ids),
            p=d.p.copy(),
            v=d.v.copy(),
            att=d.att.copy(),
            thrust=d.thrust.copy(),
            lumped=d.lumped_accel(),
            armed=[v.armed for v in self.vehicles],
            mode=[v.mode for v in self.vehicles],
            collisions=d.collisions,
            min_dist=self._min_dist,
            fences={v.id: xy for v in self.vehicles
                    if (xy := v.mission.take_fence_news()) is not None},
        )

    def publish_truth(self) -> None:
        if self.truth_pub.active:
            self.truth_pub.put(self.truth())

    def send_odometry(self, v: Vehicle) -> None:
        """The lockstep clock signal: ODOMETRY stamped t_k on the API link only (the
        controller's link; a GCS gets LOCAL_POSITION_NED at its stream rate). Sending it
        to the GCS port too doubled the simulator's sendto calls, its largest CPU cost."""
        v.outbox.append((v.odometry(self.clock.t()), ("api", None)))

    def integrate(self) -> None:
        """Step k -> k+1: state machines, commands, physics, then announce step k+1."""
        t = self.clock.t()
        clk = self.clock
        lockstep_prestart = isinstance(clk, LockstepClock) and not clk.started
        for v in self.vehicles:
            v.update(t)
            if v.release_requested and not lockstep_prestart:
                self.dyn.release(v.idx)
                v.release_requested = False
            self.dyn.set_command(v.idx, *v.command(self.dt))
        # the sub-steps in one call; the min pair distance over (t_k, t_k+1] for Truth
        self._min_dist = self.dyn.advance_period(self.substeps)
        self.clock.advance(time.monotonic())
        self._check_collisions()
        self.announce_step()

    def announce_step(self) -> None:
        """Publish truth for the current step; in lockstep send every vehicle ODOMETRY t_k."""
        self.publish_truth()
        ms = self.clock.t_ms()
        now = time.monotonic()
        for v in self.vehicles:
            v.expect_ms = ms
            if self.clock.lockstep:
                self.send_odometry(v)
                self._last_resend[v.id] = now

    def _check_collisions(self) -> None:
        pairs = self.dyn.collision_pairs
        while self._collisions_seen < len(pairs):
            t, a, b = pairs[self._collisions_seen]
            self._collisions_seen += 1
            for v in self.vehicles:
                if v.id in (a, b):
                    other = b if v.id == a else a
                    v.event(f"collision with vehicle {other}", M.MAV_SEVERITY_CRITICAL)

    # -- lockstep ---------------------------------------------------------------------
    def barrier_ready(self) -> bool:
        return all(v.active and v.answered_ms == 0 for v in self.vehicles)

    def lockstep_waiting(self) -> list[Vehicle]:
        ms = self.clock.t_ms()
        return [v for v in self.vehicles if _still_to_answer(v, ms)]

    def lockstep_poll(self, now: float) -> None:
        """One pass of the lockstep loop: start barrier, step when every answer is in, step
        anyway at the step timeout, re-send ODOMETRY t_k to whoever is late.

        The loop wakes on every datagram, so with many vehicles a scan of all of them per
        wake-up cost O(N²) per step. Between full scans (at most :data:`LOCKSTEP_SCAN_S`
        apart, and whenever the set runs empty) only the vehicles that received something
        are looked at: those that answered, or stopped being waited for, leave the set of
        the last scan. The step itself is always decided by a full scan."""
        clk = self.clock
        assert isinstance(clk, LockstepClock)
        touched, self.touched = self.touched, set()
        pending = self._pending
        if (clk.started and pending and now - self._last_full_scan < LOCKSTEP_SCAN_S
                and now < clk.deadline()):
            ms = clk.t_ms()
            by_id = self.vehicle_by_id
            for vid in touched & pending:
                if not _still_to_answer(by_id[vid], ms):
                    pending.discard(vid)
            if pending:
                return
        self._pending, self._last_full_scan = None, now
        if not clk.started:
            self._lockstep_prestart(clk, now)
            return
        if not any(v.lockstep_should_wait() for v in self.vehicles):
            # nobody to wait for (all in failsafe, disarmed or suspended): pace on the
            # wall clock instead of racing, so a client can still catch up
            if now - clk.step_started_wall >= self.dt:
                self.integrate()
            return
        waiting = self.lockstep_waiting()
        if not waiting:
            self.integrate()
            return
        if now >= clk.deadline():
            self._lockstep_timeout(waiting)
            self.integrate()
            return
        self._pending = {v.id for v in waiting}
        for v in waiting:  # a lost datagram must not cost a whole step timeout
            if now - self._last_resend.get(v.id, 0.0) >= LOCKSTEP_RESEND_S:
                self._last_resend[v.id] = now
                self.send_odometry(v)

    def _lockstep_prestart(self, clk: LockstepClock, now: float) -> None:
        """Before the barrier: offer t_0 until every vehicle answers it in OFFBOARD."""
        if self.barrier_ready():
            self.log_events()
            clk.started = True
            for v in self.vehicles:
                self.dyn.release(v.idx)
                v.release_requested = False
            self.log("lockstep: start barrier passed, all vehicles released at t_0")
            self.integrate()
            return
        if now >= self._prestart_next:  # keep offering t_0 until everyone is ready
            # at most every LOCKSTEP_RESEND_S: N waiting daemons decode every offer, and at
            # the ODOMETRY rate a few dozen of them on a few cores starve this process
            hz = self.opts.odometry_hz
            self._prestart_next = now + max(1.0 / hz if hz else 0.0, LOCKSTEP_RESEND_S)
            self.publish_truth()
            for v in self.vehicles:
                v.expect_ms = 0
                self.send_odometry(v)

    def _lockstep_timeout(self, waiting: list[Vehicle]) -> None:
        """Count a step timeout for each late vehicle; stop waiting for one after
        ``LOCKSTEP_SUSPEND_AFTER`` in a row (its next answer resumes the wait)."""
        for v in waiting:
            v.ctr.lockstep_timeouts += 1
            v.consecutive_timeouts += 1
            self.lockstep_timeouts += 1
            if v.consecutive_timeouts >= LOCKSTEP_SUSPEND_AFTER and not v.wait_suspended:
                v.wait_suspended = True
                v.event(f"lockstep: no answer for {v.consecutive_timeouts} steps, not waiting")

    def next_wakeup(self, now: float) -> float:
        if isinstance(self.clock, RealTimeClock):
            t = self.clock.next_deadline()
        elif not self.clock.started:
            t = min(self._prestart_next, now + 0.02)
        else:
            t = min(self.clock.deadline(), now + LOCKSTEP_RESEND_S)
        return max(0.0, min(t - now, 0.01))

    def run(self) -> int:
        """Run until SIGINT/SIGTERM (``stop_requested``) or ``duration``. Returns exit code."""
        o = self.opts
        self.log(
            f"{len(self.vehicles)} vehicles, {'lockstep' if o.lockstep else 'real-time'}, "
            f"control {1 / self.dt:.0f} Hz, physics {self.substeps}x, port offset {o.port_offset}"
        )
        if isinstance(self.clock, RealTimeClock):
            self.clock.t0 = time.monotonic()
        else:
            self.clock.begin_step()
        self.announce_step()
        skip = (MSG_ODOMETRY,) if o.lockstep else ()
        try:
            while not self.stop_requested:
                now = time.monotonic()
                self.receive(self.next_wakeup(now))
                now = time.monotonic()
                if isinstance(self.clock, RealTimeClock):
                    n = 0
                    while self.clock.due(now) and n < 5:
                        self.integrate()
                        n += 1
                    if n == 5 and self.clock.due(now):
                        self.clock.t0 = now - self.clock.k * self.dt
                        self.clock.relocks += 1
                else:
                    self.lockstep_poll(now)
                t = self.clock.t()
                # lockstep: the wall-clock telemetry and reports are scanned at most every
                # LOCKSTEP_SCAN_S (the loop wakes on every setpoint: with 64 vehicles the
                # per-vehicle scan on each wake-up cost more than the physics); real time:
                # every pass, ODOMETRY is one of these streams there
                if not o.lockstep or now - self._last_scan >= LOCKSTEP_SCAN_S:
                    self._last_scan = now
                    if o.signing_key is not None:
                        self.report_rejects(now)
                    for v in self.vehicles:
                        v.periodic(now, t, skip, self.live_peers(v), self.heartbeat_only(v))
                self.flush(now)
                if o.duration is not None and t >= o.duration - 1e-9:
                    self.log(f"duration {o.duration} s reached")
                    break
        finally:  # the result line, not a diagnostic: printed at every --log-level
            if o.stats_out:
                self.write_stats(o.stats_out)
            print(f"[vehicle-sim t={self.clock.t():.2f}] {self.summary()}",
                  file=sys.stderr, flush=True)  # fmt: skip
        return 0

    def write_stats(self, path: str) -> None:
        stats.write_stats(self, path)

    def summary(self) -> str:
        return stats.summary(self)

    def states_finite(self) -> bool:
        d = self.dyn
        return bool(all(np.all(np.isfinite(a)) for a in (d.p, d.v, d.att, d.thrust)))
