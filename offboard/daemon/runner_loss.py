"""Runner or router lost (real time): brake and hold, then the coordinated landing on
odometry alone.

Policy (docs/security.md, "Losing the runner or the router"; docs/lifecycle.md, "Landing
after losing the router"), in the vehicle's clock (mission time from its ODOMETRY stamps;
one simulator or one GPS time base, so the same on every vehicle):

1. **Stalled.** Truth more than ``STALLED_PERIODS`` control steps (0.2 s at 50 Hz)
   behind the vehicle's step: the daemon stops stepping its agent on the stale truth and at
   once streams a brake-and-hold from its vehicle's own ODOMETRY (:class:`OdometryFlight`
   on a :class:`HoldReference` at the position measured at that step). The vehicle stays
   in OFFBOARD. Truth within ``STALLED_PERIODS`` again: the agent steps again (a loaded
   host may stall truth for a moment; the hold is the safe answer to that too).
   **Lost.** More than ``RUNNER_LOST_PERIODS`` (0.5 s) behind: the runner or router is
   gone; the hold goes on and the land time is set. Before, the daemon flew the stale truth
   for the whole 0.5 s and then stopped streaming, leaving the vehicle on its last attitude
   setpoint until its offboard-loss failsafe (0.5 s more) and PX4's HOLD: about a second
   with nobody steering, in which two vehicles met on a loaded host.
2. **Land time.** t_L = t_s + ``land_after_s``, t_s = the time of the last truth step this
   daemon saw. Every daemon loses the router at the same instant, so their t_s differ only
   by the truth steps in flight when it died (one or two control periods); see
   :func:`loss_landing_plan` for why that disagreement is harmless and why it is not
   quantised.
3. **Commit.** From t_L − ``LEAD_S`` on, the landing is decided: the same PD +
   feed-forward controller (its disturbance estimate kept) now flies a landing reference
   that starts at rest at the vehicle's measured position. Truth coming back before the
   commit: normal flight resumes. After the commit the landing is finished whatever
   happens on Zenoh. A failsafe HOLD on the way (a stalled host) is taken back to OFFBOARD
   by the recovery policy (offboard.daemon.mavlink.offboard_keeper.OffboardKeeper).
4. **Landing.** From t_L the reference flies this agent's slot of the coordinated
   landing plan (offboard.agent.landing): its pad and its descent delay, lowest first.
5. **Landed.** Once the reference ended ``LANDED_SETTLE_S`` ago and the vehicle is below
   ``LANDED_Z``: idle command, then a (non-forced) disarm.

Lockstep runs do not use this: their simulator cannot move without its controllers.
Positions ENU, z up (m, s, m/s²).
"""

from __future__ import annotations

import enum
import logging
from dataclasses import replace

import numpy as np

from offboard.agent.landing import LandingPlan, LandingReference, landed, landing_plan
from offboard.daemon.limits import LAND_AFTER_S, MIN_LAND_AFTER_S
from offboard.estimation.reference import xi_a, xi_at_rest, xi_j, xi_p, xi_v
from offboard.inner_loop.attitude import Setpoint, setpoint_from_accel
from swarm_common.scenario.input_set import control_box
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

STALLED_PERIODS = 10  # real time: truth this many steps behind the vehicle -> brake, hold
RUNNER_LOST_PERIODS = 25  # ... this many: the runner or router is lost -> land at t_L
LEAD_S = 1.0  # s before t_L the landing is committed
DISARM_AFTER_S = 1.0  # s of landed idle before the disarm (retried every 2 s while armed)


class LossPhase(enum.Enum):
    """Internal state of :class:`RunnerLoss` (never on a wire or in a file)."""

    FLYING = "flying"  # truth fresh: the agent steps
    STALLED = "stalled"  # truth late: the daemon brakes and holds on its own odometry
    HOLDING = "holding"  # truth lost: that hold goes on, the land time is set
    LANDING = "landing"  # committed: the daemon flies its landing slot to the ground


def loss_landing_plan(sc: Scenario, t_s: float, t_land: float) -> LandingPlan:
    """The coordinated landing plan of offboard.agent.landing for pads planned at t_s (where the
    formation was when truth stopped; the vehicles hold near it) and timing from t_land.

    Why t_s is not quantised: a grid makes daemons whose t_s straddle a grid line disagree
    by a whole grid step, while the raw t_s disagree only by the truth steps in flight when
    the router died (δ, one or two control periods). Each agent's pad is its own footprint
    at t_s (+ the plan's outward offset for upper agents), so a disagreement δ moves each
    pad by at most the formation's speed × δ (cube8: < 1 m/s × 0.04 s), far inside the
    pads' 0.25 m margin over 2·D_safe; the descent delays (lower agents first, upper ones
    only once past the pad below, ≥ 1.5 s) dwarf δ. Not covered: scenarios whose stack or
    altitude order changes within δ (two agents at nearly equal planned altitude, or
    footprints at nearly the pad separation), where two daemons may rank them differently.
    """
    return replace(landing_plan(sc, t_s), t_land=t_land)


class RunnerLoss:
    """Detection of a stalled or lost runner/router and the land time (module docstring).

    ``land_after_s`` = 0: never land (hold until truth is back, the behaviour before)."""

    def __init__(self, control_hz: int, land_after_s: float = LAND_AFTER_S) -> None:
        if land_after_s != 0.0 and not (MIN_LAND_AFTER_S <= land_after_s <= 3600.0):
            raise ValueError(f"land_after_s = {land_after_s!r}: 0 (never) or "
                             f"{MIN_LAND_AFTER_S}..3600 s")
        self.control_hz = control_hz
        self.land_after_s = land_after_s
        self.phase = LossPhase.FLYING
        self.t_s: float | None = None  # time of the last truth step seen when lost
        self.episode = 0  # count of stalls (each one holds where it began)
        self.max_lag = 0  # the largest k − truth step seen while flying (periods)
        self.sticky = False  # a navigation fault: never back to flying on the agent

    @property
    def lost(self) -> bool:
        """Not flying on truth: stalled, lost or landing (the daemon flies LossFlight)."""
        return self.phase is not LossPhase.FLYING

    @property
    def landing(self) -> bool:
        return self.phase is LossPhase.LANDING

    @property
    def t_land(self) -> float | None:
        if self.t_s is None or self.land_after_s == 0.0:
            return None
        return self.t_s + self.land_after_s

    def observe(self, k: int, truth_step: int | None) -> str | None:
        """The vehicle is at step ``k``, the latest truth is of ``truth_step`` (None: none
        yet). Returns "stalled", "lost" or "back" on a change, else None; once landing,
        None."""
        if self.phase is LossPhase.LANDING or truth_step is None or self.sticky:
            return None
        lag = k - truth_step
        if lag <= STALLED_PERIODS:
            self.max_lag = max(self.max_lag, lag)
            if self.phase is LossPhase.FLYING:
                return None
            self.phase, self.t_s = LossPhase.FLYING, None
            return "back"
        if lag > RUNNER_LOST_PERIODS and self.phase is not LossPhase.HOLDING:
            self.episode += self.phase is LossPhase.FLYING
            self.phase = LossPhase.HOLDING
            self.t_s = truth_step / self.control_hz
            return "lost"
        if self.phase is LossPhase.FLYING:
            self.phase = LossPhase.STALLED
            self.episode += 1
            return "stalled"
        return None

    def navigation_fault(self, t: float) -> None:
        """The agent's own estimate diverged at t (s; :mod:`offboard.daemon.nav_check`): the same
        brake-and-hold on odometry and land time as a lost runner (t_s = t), and no way
        back to the agent, whatever truth does."""
        if self.phase is LossPhase.LANDING or self.sticky:
            return
        self.sticky = True
        self.episode += self.phase is LossPhase.FLYING
        self.phase = LossPhase.HOLDING
        self.t_s = t

    def commit_due(self, t: float) -> bool:
        """Holding and t ≥ t_L − LEAD_S: time to start the landing (then call commit)."""
        t_land = self.t_land
        return self.phase is LossPhase.HOLDING and t_land is not None and t >= t_land - LEAD_S

    def commit(self) -> None:
        self.phase = LossPhase.LANDING


def landing_reference(sc: Scenario, index: int, t_s: float, t_land: float,
                      p_hold: np.ndarray) -> LandingReference:
    """Agent ``index``'s slot of the loss landing plan, started at rest at ``p_hold``."""
    return LandingReference(loss_landing_plan(sc, t_s, t_land), index, xi_at_rest(p_hold))


class HoldReference:
    """ξ(t) at rest at ``p`` (m, ENU) for ever: the brake-and-hold before the commit."""

    def __init__(self, p: np.ndarray) -> None:
        self.xi0 = xi_at_rest(p)

    def xi(self, t: float) -> np.ndarray:
        return self.xi0

    def ended(self, t: float) -> bool:
        return False


class OdometryFlight:
    """PD + feed-forward of one agent on a reference (a :class:`HoldReference`, then its
    slot of the loss landing plan), with the vehicle's own ODOMETRY as the only state
    source (no truth, no neighbours).

    Control (ENU, m/s²), as the leaders' (docs/architecture.md, offboard.agent.leader):
    u = a* + τ j* − d̂ + k_p (p* − p) + k_d (v* − v), clipped to the control box, with a
    velocity ESO d̂ for the disturbance and ground effect (double pole at −5 rad/s);
    idle (lowest vertical acceleration, no tilt) once landed (offboard.agent.landing.landed)."""

    L1, L2 = 10.0, 25.0  # velocity ESO gains (as offboard.agent.leader)

    def __init__(self, sc: Scenario, ref: LandingReference | HoldReference) -> None:
        self.ref = ref
        self.veh = sc.vehicle
        self.kp, self.kd = sc.controller.leader_kp, sc.controller.leader_kd
        self.u_lo, self.u_hi = control_box(sc.vehicle, sc.controller)
        self.dt = sc.control_dt
        self.v_hat: np.ndarray | None = None
        self.d_hat = np.zeros(3)
        self.u_prev = np.zeros(3)

    @classmethod
    def landing(cls, sc: Scenario, index: int, t_s: float, t_land: float,
                p_hold: np.ndarray) -> OdometryFlight:
        """Agent ``index``'s slot of the loss landing plan (t_s, t_land), its reference
        started at rest at ``p_hold`` with t0 = t_L (held there before t_L)."""
        return cls(sc, landing_reference(sc, index, t_s, t_land, p_hold))

    @property
    def pad(self) -> np.ndarray:
        """The landing pad (x, y) (m); only for a landing reference."""
        assert isinstance(self.ref, LandingReference)
        return np.array(self.ref.p1[:2])

    def landed(self, t: float, z: float) -> bool:
        return isinstance(self.ref, LandingReference) and landed(self.ref, t, z)

    def command(self, t: float, p: np.ndarray, v: np.ndarray) -> tuple[Setpoint, np.ndarray]:
        """The setpoint (and its u) for the measured position p and velocity v at t."""
        self._update_eso(v)
        ref = self.ref.xi(t)
        a_ff = xi_a(ref) + self.veh.tau_rollpitch_s * xi_j(ref)
        u = a_ff - self.d_hat + self.kp * (xi_p(ref) - p) + self.kd * (xi_v(ref) - v)
        u = np.clip(u, self.u_lo, self.u_hi)
        if self.landed(t, float(p[2])):
            u = np.array([0.0, 0.0, self.u_lo[2]])
        self.u_prev = u
        return setpoint_from_accel(u, 0.0, self.veh), u

    def _update_eso(self, v: np.ndarray) -> None:
        """v̂' = u + d̂ + l1 (v − v̂), d̂' = l2 (v − v̂) over one period (Euler, u held)."""
        if self.v_hat is None:
            self.v_hat = np.array(v, dtype=float)
            return
        err = v - self.v_hat
        self.v_hat = self.v_hat + self.dt * (self.u_prev + self.d_hat + self.L1 * err)
        self.d_hat = self.d_hat + self.dt * self.L2 * err
        if not (np.all(np.isfinite(self.d_hat)) and np.all(np.isfinite(self.v_hat))):
            self.v_hat, self.d_hat = np.array(v, dtype=float), np.zeros(3)


class LossFlight:
    """What a daemon flies once its runner or router is lost (module docstring): at once a
    brake-and-hold at the position measured when the loss was seen, from the commit on its
    slot of the landing plan, then idle and a disarm."""

    def __init__(self, sc: Scenario, index: int, agent_id: int, loss: RunnerLoss) -> None:
        self.sc, self.index, self.id = sc, index, agent_id
        self.loss = loss
        self.flight: OdometryFlight | None = None
        self.flight_episode = 0  # the stall (RunnerLoss.episode) the flight belongs to
        self.idle_since: float | None = None  # vehicle clock (s) of the landed idle

    @property
    def lander(self) -> OdometryFlight | None:
        """The committed landing flight (None before the commit)."""
        return self.flight if self.loss.landing else None

    def setpoint(self, t: float, p: np.ndarray, v: np.ndarray) -> Setpoint | None:
        """The setpoint at vehicle time t for the measured p, v; None while flying."""
        if not self.loss.lost:
            return None
        if self.flight is None or self.flight_episode != self.loss.episode:  # a new stall
            self.flight = OdometryFlight(self.sc, HoldReference(p))
            self.flight_episode = self.loss.episode
            log.warning("agent %d: %s at t=%.2f s: braking to a hold at "
                        "(%.2f, %.2f, %.2f) on odometry", self.id,
                        "estimate diverged" if self.loss.sticky else "truth late", t, *p)
        t_s, t_land = self.loss.t_s, self.loss.t_land
        if self.loss.commit_due(t) and t_s is not None and t_land is not None:
            self.loss.commit()
            self.flight.ref = landing_reference(self.sc, self.index, t_s, t_land, p)
            pad = self.flight.pad
            log.warning("agent %d: %s since t=%.2f s: landing on odometry, t_L=%.2f s, "
                        "pad (%.2f, %.2f)", self.id,
                        "estimate diverged" if self.loss.sticky else "runner/router lost",
                        t_s, t_land, pad[0], pad[1])
        return self.flight.command(t, p, v)[0]

    def disarm_due(self, t: float, z: float, armed: bool) -> bool:
        """True when a disarm should be asked for now: landed idle for DISARM_AFTER_S
        (again every 2 s while the vehicle stays armed)."""
        if self.lander is None or not self.lander.landed(t, z):
            self.idle_since = None
            return False
        if self.idle_since is None:
            self.idle_since = t
            log.info("agent %d: landed at t=%.2f s (z=%.3f m): idle", self.id, t, z)
        if armed and t - self.idle_since >= DISARM_AFTER_S:
            self.idle_since = t + 1.0
            return True
        return False
