"""Coordinated land-all: a landing plan every agent computes alone, and the smooth
landing reference ξ(t) = [p*, v*, a*, j*] its nominal controller + safety filter track.

Plan (:func:`landing_plan`), deterministic from the scenario and the land time t_L only
(no communication): the formation's desired positions at t_L (leaders' trajectory at t_L,
followers p* = −L_ff⁻¹ L_fl p_L) are projected on the ground. Agents whose projections lie
within 2·D_safe of each other form a *stack*; in each stack, lowest first, the lowest keeps
its footprint as pad and the k-th above it gets a pad pushed outward (away from the
formation's horizontal centroid) by k·``offset`` m, further if needed, until every pad is at
least ``2·D_safe`` (+ margin) from every other pad.

Timing: one common horizontal transit time ``T_h`` (min-jerk, peak speed ≤ ``v_h``); the
stack bottoms descend at once, the k-th of a stack starts descending once its transit has
carried it ``(k − ½)·offset`` away from the stack (past the pad of the one below), so the
lower vehicles are always first and nobody descends onto another.

Reference of one agent (:class:`LandingReference`), from its reference state (p0, v0, a0)
at t_L: horizontal quintic (p0, v0, a0) → (pad, 0, 0) over T_h; vertical quintic
(z0, vz0, az0) → (z0, 0, 0) over T_h plus a descent of z0 m at speed ``v_d`` (m/s) with
smoothstep velocity ramps of ``tau_r`` s (acceleration ≤ 1.5 v_d/τ_r), ending at z = 0.
All ENU, z up (m, s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offboard.agent.governor import governor_for
from offboard.agent.takeoff import TAU_R, leader_origin, ramped_travel
from offboard.estimation.bearing import Formation, formation_from_scenario
from offboard.estimation.reference import LeaderTrajectory, xi_a, xi_p, xi_v
from swarm_common.scenario.model import Scenario

V_H = 1.5  # m/s, peak horizontal transit speed
V_D = 0.6  # m/s, descent speed
T_H_MIN = 2.0  # s, shortest horizontal transit
PAD_MARGIN = 0.25  # m, added to 2·D_safe between pads
LANDED_Z = 0.08  # m, an agent below this after its reference ended is landed ...
LANDED_SETTLE_S = 1.0  # s, ... once the reference has been at rest on the pad this long
MINJERK_PEAK = 1.875  # peak speed of the min-jerk profile per (distance / duration)


@dataclass(frozen=True)
class LandingPlan:
    """Common plan: per scenario index a pad (N,2) (m), descent start delay (N,) (s) after
    t_L, the horizontal transit time ``t_h`` (s) and the land time ``t_land`` (s)."""

    t_land: float
    pads: np.ndarray
    descent_delay: np.ndarray
    t_h: float
    min_pad_sep: float


def min_jerk(x: float) -> tuple[float, float, float, float]:
    """s, s', s'', s''' of 10x³ − 15x⁴ + 6x⁵ on x ∈ [0, 1] (clamped outside)."""
    if x <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    if x >= 1.0:
        return 1.0, 0.0, 0.0, 0.0
    return (
        x**3 * (10.0 - 15.0 * x + 6.0 * x * x),
        30.0 * x * x * (1.0 - x) ** 2,
        60.0 * x * (1.0 - 3.0 * x + 2.0 * x * x),
        60.0 * (1.0 - 6.0 * x + 6.0 * x * x),
    )


def _fraction_at(dist: float) -> float:
    """x with min_jerk(x) = dist ∈ [0, 1] (bisection)."""
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if min_jerk(mid)[0] < dist:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def planned_positions(sc: Scenario, t_land: float, form: Formation | None = None) -> np.ndarray:
    """(N,3) desired formation positions at t_land (leaders on their trajectory)."""
    form = form if form is not None else formation_from_scenario(sc)
    lt = sc.leader_trajectory
    lead = np.array([
        LeaderTrajectory(leader_origin(sc, i), np.array(lt.amplitude_m),
                         governor_for(sc).frequency_hz)
        .state(t_land)[0:3]
        for i in form.leader_idx
    ])
    return form.desired_positions(lead)


def _stacks(xy: np.ndarray, sep: float) -> list[int]:
    """Stack label per agent: union of agents whose projections are closer than ``sep``."""
    n = len(xy)
    lab = list(range(n))

    def root(i: int) -> int:
        while lab[i] != i:
            i = lab[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            if np.linalg.norm(xy[i] - xy[j]) < sep:
                lab[max(root(i), root(j))] = min(root(i), root(j))
    return [root(i) for i in range(n)]


def _last_leg(start: np.ndarray, pad: np.ndarray, length: float) -> np.ndarray:
    """Points on the last ``length`` metres of the straight transit start → pad (where the
    descent of a stacked agent begins, :func:`landing_plan`'s timing)."""
    d = pad - start
    n = float(np.linalg.norm(d))
    if n < 1e-9:
        return pad[None, :]
    s0 = max(0.0, 1.0 - length / n)
    return start + np.linspace(s0, 1.0, 11)[:, None] * d


def _crowded(
    pad: np.ndarray, start: np.ndarray, i: int, placed: list[int], pads: np.ndarray,
    xy: np.ndarray, sep: float, clear: float,
) -> bool:
    """Whether pad ``pad`` of agent ``i`` is closer than ``sep`` to a placed pad, or the
    last leg of its transit (where it may already descend) passes closer than ``clear``
    to a placed pad, or it lies closer than ``clear`` to the last leg of a placed agent's
    transit. Large sparse formations (grid64: a centre column pushed outward along the
    same diagonal as a corner column) need the last two: their pads would otherwise sit
    under another agent's descent."""
    for j in placed:
        if np.linalg.norm(pad - pads[j]) < sep:
            return True
        if i != j and np.min(np.linalg.norm(_last_leg(start, pad, sep) - pads[j], axis=1)) < clear:
            return True
        if np.any(pads[j] != xy[j]):
            leg = _last_leg(xy[j], pads[j], sep)
            if np.min(np.linalg.norm(leg - pad, axis=1)) < clear:
                return True
    return False


def landing_plan(sc: Scenario, t_land: float, form: Formation | None = None) -> LandingPlan:
    """The common landing plan at t_land (module docstring)."""
    p = planned_positions(sc, t_land, form)
    xy = p[:, :2]
    d_safe = sc.controller.d_safe_m
    sep = 2.0 * d_safe + PAD_MARGIN
    offset = 2.0 * sep
    centre = xy.mean(axis=0)
    stack = _stacks(xy, sep)
    pads = np.zeros_like(xy)
    rank = np.zeros(len(xy), dtype=int)
    placed: list[int] = []
    for i in sorted(range(len(xy)), key=lambda i: (p[i, 2], sc.agents[i].id)):
        rank[i] = sum(1 for j in placed if stack[j] == stack[i])
        out = xy[i] - centre
        nrm = float(np.linalg.norm(out))
        out = out / nrm if nrm > 1e-6 else np.array([1.0, 0.0])
        k = rank[i]
        pad = xy[i] + k * offset * out
        while _crowded(pad, xy[i], i, placed, pads, xy, sep, 2.0 * d_safe):
            k += 1
            pad = xy[i] + k * offset * out
        pads[i] = pad
        placed.append(i)
    move = np.linalg.norm(pads - xy, axis=1)
    t_h = max(T_H_MIN, MINJERK_PEAK * float(move.max()) / V_H)
    delay = np.zeros(len(xy))
    for i in range(len(xy)):
        if rank[i] > 0 and move[i] > 0.0:
            clear = min(1.0, (move[i] - 0.5 * offset) / move[i])
            delay[i] = t_h * _fraction_at(max(clear, 0.5))
    return LandingPlan(float(t_land), pads, delay, t_h, sep)


class LandingReference:
    """ξ(t) of one agent (module docstring); ``xi0`` is its reference state at t_land."""

    def __init__(self, plan: LandingPlan, index: int, xi0: np.ndarray) -> None:
        self.plan = plan
        self.t0 = plan.t_land
        self.p0 = np.array(xi_p(xi0), dtype=float)
        v0, a0 = np.array(xi_v(xi0), dtype=float), np.array(xi_a(xi0), dtype=float)
        self.p1 = np.array([plan.pads[index, 0], plan.pads[index, 1], self.p0[2]])
        self.t_h = plan.t_h
        self.coef = [_quintic(self.p0[k], v0[k], a0[k], self.p1[k], self.t_h) for k in range(3)]
        self.delay = float(plan.descent_delay[index])
        self.dz = max(0.0, float(self.p0[2]))
        self.t_end = self.t0 + max(self.t_h, self.delay + self.dz / V_D + TAU_R)

    def xi(self, t: float) -> np.ndarray:
        """[p*, v*, a*, j*] (12,) at mission time t (held at the pad after the end)."""
        s = min(max(t - self.t0, 0.0), self.t_h)
        out = np.zeros(12)
        for k in range(3):
            c = self.coef[k]
            out[k], out[3 + k], out[6 + k], out[9 + k] = _poly(c, s)
            if t - self.t0 >= self.t_h:
                out[3 + k] = out[6 + k] = out[9 + k] = 0.0
        d, v, a, j = ramped_travel(t - self.t0 - self.delay, self.dz, V_D)
        out[2] -= d
        out[5] -= v
        out[8] -= a
        out[11] -= j
        return out

    def ended(self, t: float) -> bool:
        """The reference is at rest on the ground (from t_end on)."""
        return t >= self.t_end


def _quintic(p0: float, v0: float, a0: float, p1: float, T: float) -> np.ndarray:
    """Coefficients c0..c5 of the quintic (p0, v0, a0) → (p1, 0, 0) over T s."""
    d = p1 - p0 - v0 * T - 0.5 * a0 * T * T
    m = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4],
                  [6 * T, 12 * T**2, 20 * T**3]])
    c345 = np.linalg.solve(m, np.array([d, -v0 - a0 * T, -a0]))
    return np.array([p0, v0, 0.5 * a0, *c345])


def _poly(c: np.ndarray, s: float) -> tuple[float, float, float, float]:
    """Value and first three derivatives of Σ c_k s^k at s."""
    p = sum(float(c[k]) * s**k for k in range(6))
    v = sum(k * float(c[k]) * s ** (k - 1) for k in range(1, 6))
    a = sum(k * (k - 1) * float(c[k]) * s ** (k - 2) for k in range(2, 6))
    j = sum(k * (k - 1) * (k - 2) * float(c[k]) * s ** (k - 3) for k in range(3, 6))
    return p, v, a, j


def landed(ref: LandingReference | None, t: float, z: float) -> bool:
    """True once ``ref`` has ended LANDED_SETTLE_S ago and the agent's altitude z (m) is
    below LANDED_Z: the agent first settles on the pad under its controller (the reference
    ends at rest at z = 0), then idles; idling at the end of the reference dropped a
    vehicle still a few cm up onto the ground at up to 0.9 m/s."""
    return ref is not None and ref.ended(t - LANDED_SETTLE_S) and z < LANDED_Z

