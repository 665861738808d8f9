"""How fast a pair can close when it comes into sensing range: the part of the load-time
check (b) (:mod:`swarm_common.scenario.safety_check`, docs/safety.md §5d and §5i) that the
followers' transient speed limit ``controller.max_transient_speed_mps`` = v_t makes
checkable. Pure functions of the scenario and of numbers.

Why: a pair gets barrier rows only once sensed. While every pair is within range from the
start and in the formation, (b) needs only the closing speed the file fixes (initial
speeds and the reference). Once the range is shorter than the swarm, pairs come into range
during the acquisition, and a follower far from its vertex flies as fast as its gains ask:
nothing in the file bounds it unless v_t does.

**Span.** Pairs can come into range in flight when ``formation.sensing_range_m`` is below
the largest distance between two agents at the start or in the formation (the desired
positions at t = 0, :func:`swarm_common.scenario.feasibility.desired_origins`; the
reference moves the formation as a whole, so its distances stay).

**Closing speed with v_t.** A dcbf follower keeps e_i = v_i − v*_i at ‖e_i‖ ≤ v_t
(offboard.safety.dcbf.speed_rows), or at most its initial speed s_f when it starts faster
(its rows then only slow it down; ξ̂ starts at rest, so e_i(0) = v_i(0)). The desired
velocities v*_i are the observers' estimates of the common reference motion, so, as in
(b), two of them differ by at most the reference's peak speed v_ref while one lags it. A
leader flies its reference with its PD, off it by at most its initial speed s_l (it starts
on its reference, at rest on it). So with u_f = max(v_t, s_f):

    follower–follower:  ‖Δv‖ ≤ ‖v*_i − v*_j‖ + ‖e_i‖ + ‖e_j‖ ≤ v_ref + 2 u_f
    follower–leader:    ‖Δv‖ ≤ v_ref + u_f + s_l

and v̄ = v_ref + max(2 u_f, u_f + s_l), or the start's v̄ of (b) when that is larger.

**The largest v_t.** max(R_h, R_b) of (b) grows with v̄, so the range R allows every
v̄ ≤ v̄_R, the smaller of the roots of R_h(v̄) = R and R_b(v̄) = R (:func:`speed_for_range`),
and v_t ≤ min((v̄_R − v_ref)/2, v̄_R − v_ref − s_l) (:func:`largest_transient_speed`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from swarm_common.memo import IdentityMemo
from swarm_common.scenario.feasibility import desired_origins
from swarm_common.scenario.graphs import formation_scale

if TYPE_CHECKING:
    from swarm_common.scenario.spec import Scenario

_SPANS: IdentityMemo[float] = IdentityMemo()


def widest(*layouts: np.ndarray) -> float:
    """The largest distance (m) between two agents of any of the (N, 3) ``layouts``."""
    return max(float(np.max(np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)))
               for p in layouts)


def span(sc: Scenario) -> float:
    """The largest distance (m) between two agents at the start or in the formation (once
    per scenario object: the load check asks several times)."""
    return _SPANS.get(sc, (), lambda: _span(sc))


def _span(sc: Scenario) -> float:
    p0 = sc.initial_positions()
    want = desired_origins(sc)
    if want is None:  # the formation does not fix the followers: the scaled vertices
        k1, k2 = (sc.index_of(i) for i in sc.formation.leaders[:2])
        want = sc.vertices() * formation_scale(p0, sc.vertices(), k1, k2)
    return widest(p0, want)


def start_speeds(sc: Scenario) -> tuple[float, float]:
    """(s_f, s_l): the largest initial speed (m/s) of a follower and of a leader."""
    v = np.linalg.norm(sc.initial_velocities(), axis=1)
    lead = np.array([a.is_leader for a in sc.agents])
    s_f = float(v[~lead].max()) if (~lead).any() else 0.0
    s_l = float(v[lead].max()) if lead.any() else 0.0
    return s_f, s_l


def limited_closing_speed(v_t: float, v_ref: float, s_f: float, s_l: float) -> float:
    """v̄ (m/s) of a pair that comes into range with the followers' limit v_t (module
    docstring): v_ref + max(2 u_f, u_f + s_l), u_f = max(v_t, s_f)."""
    u_f = max(v_t, s_f)
    return v_ref + max(2.0 * u_f, u_f + s_l)


def speed_for_range(r: float, tau_s: float, d: float, a_b: float, lag: float) -> float:
    """The largest v̄ (m/s) at which a pair heard at ``r`` (m) is safe by (b): h ≥ 0 there,
    r ≥ τ_s v̄ + √(τ_s² v̄² + d²), i.e. v̄ ≤ (r² − d²)/(2 τ_s r); and it stops before d,
    r ≥ d + v̄ lag + v̄²/(2 a_b) (``lag`` = dt + τ, s). 0 when r ≤ d or a_b ≤ 0."""
    if r <= d or a_b <= 0.0:
        return 0.0
    v_h = math.inf if tau_s <= 0.0 else (r * r - d * d) / (2.0 * tau_s * r)
    v_b = a_b * (math.sqrt(lag * lag + 2.0 * (r - d) / a_b) - lag)
    return min(v_h, v_b)


def entry_distance(v_bar: float, tau_s: float, d: float) -> float:
    """R_h (m) of (b): the distance at which a pair closing head-on at ``v_bar`` (m/s) has
    h = 0, τ_s v̄ + √(τ_s² v̄² + d²)."""
    return tau_s * v_bar + math.sqrt((tau_s * v_bar) ** 2 + d * d)


def stop_distance(v_bar: float, d: float, a_b: float, lag: float) -> float:
    """R_b (m) of (b): d + v̄ lag + v̄²/(2 a_b), the distance in which a pair closing at
    ``v_bar`` (m/s) stops before ``d`` braking at ``a_b`` (m/s²) after ``lag`` (s); inf when
    a_b ≤ 0."""
    if a_b <= 0.0:
        return math.inf
    return d + v_bar * lag + v_bar * v_bar / (2.0 * a_b)


def pair_reach(v_bar: float, tau_s: float, d: float, a_b: float, lag: float) -> float:
    """max(R_h, R_b) (m) of (b) for a pair closing at ``v_bar`` (m/s): the distance from
    which it must have barrier rows (:func:`entry_distance`, :func:`stop_distance`); the
    inverse of :func:`speed_for_range`."""
    return max(entry_distance(v_bar, tau_s, d), stop_distance(v_bar, d, a_b, lag))


def largest_transient_speed(v_range: float, v_ref: float, s_l: float) -> float:
    """The largest v_t (m/s) with v_ref + max(2 v_t, v_t + s_l) ≤ ``v_range``; may be ≤ 0
    (no v_t helps)."""
    return min(0.5 * (v_range - v_ref), v_range - v_ref - s_l)
