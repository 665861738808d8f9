"""Load-time safety assumptions of a scenario (docs/safety.md, "Load-time checks"). Pure.

Each check returns one line naming the scenario key(s), the value and the derived bound, or
None. :func:`safety_problems` lists every broken one; the loader
(:func:`swarm_common.scenario.checks.check_safe`) refuses the scenario with the first, or
with ``--allow-unsafe`` logs each as a warning. Notation: D = ``controller.d_safe_m``,
τ_s = ``controller.tau_safe_s``, τ = ``vehicle.tau_rollpitch_s``, dt = 1/``control_hz``,
the barrier h = ‖Δp‖² + 2τ_s ΔvᵀΔp − D² (docs/safety.md §1).

With κ = ``controller.dcbf_vertical_scale`` > 1 (docs/safety.md §4c) the barrier is that of
S Δp, S Δv, S = diag(1, 1, 1/κ): (a) evaluates it so, and (b), (d) take the distance along
z, κD, wherever D enters (the worst direction: R_h and R_b grow with D), for every method.

(a) **Start inside the safe set.** The filter's claim (§5) is invariance of {h ≥ 0}: it
    holds from t = 0 only if every pair starts with h(0) ≥ 0 and ‖Δp(0)‖ ≥ D.

(b) **Sensing range vs braking distance.** A pair gets a barrier row only once sensed. Let
    v̄ bound the closing speed (:func:`closing_speed`). Heard at distance R while closing
    at v̄, the pair must (i) be in the safe set, h ≥ 0 head-on: R² − 2τ_s v̄ R − D² ≥ 0,
    i.e. R ≥ τ_s v̄ + √(τ_s² v̄² + D²); and (ii) be able to stop before D. One agent
    brakes (against a leader, or a neighbour that does not, §5b) with the horizontal
    authority a_b = min(u_max, g tanθ cos(π/K)) − F_d/m (input set §3 at hover, less the
    disturbance). It reacts one period late (dt), and the first-order lag makes the
    acceleration −a_b(1 − e^{−t/τ}); integrating, the distance to stop is
    v̄²/(2a_b) + v̄τ − a_bτ²/2 ≤ v̄²/(2a_b) + v̄τ. So R ≥ D + v̄(dt + τ) + v̄²/(2a_b).

(c) **Attitude lag vs the control loop.** Per axis the follower's nominal control
    (offboard.safety.clf_kernel) closes e1 = p − p* with ë1 = u − a* and
    u = a* − c1 ė1 − c0 e1, c1 = λ + k_s, c0 = k_s λ + k_p/k_d; the lag ȧ = (u − a)/τ
    and the zero-order hold (half a period of delay, to first order one more lag dt/2)
    give τ_e s³ + s² + c1 s + c0, τ_e = τ + dt/2. Routh–Hurwitz: stable iff c1 > τ_e c0.
    A lag margin of :data:`LAG_MARGIN` is required (the loop stays stable with the lag
    doubled): τ_e ≤ c1/(2 c0). The leaders' PD (c1 = leader_kd, c0 = leader_kp) likewise.

(d) **Noise vs the margin ē.** The filter estimates the relative acceleration by
    differencing the sensed Δv and low-passing it with weight ½ (§4): the impulse response
    of ½(1 − z⁻¹)/(1 − ½z⁻¹) has Σh² = 1/3, so white Δv noise of norm-RMS σ_v gives an
    acceleration error of RMS σ_v/(√3 dt). The sensed Δv = ġ d + g ḋ carries
    ``range_rate_noise_mps`` along g and d·``bearing_rate_noise_radps`` on each of the three
    axes: σ_v² = σ_ḋ² + 3 d² σ_ġ², taken at the distance R_h of (b)(i), where h first can
    be 0 (closer pairs have less). ē = ``dcbf_accel_error_mps2`` must cover
    :data:`NOISE_SIGMAS` standard deviations of it (A3).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from swarm_common.barrier import barrier
from swarm_common.enums import StartMode
from swarm_common.scenario.input_set import InputSet
from swarm_common.scenario.transient_check import (
    entry_distance,
    largest_transient_speed,
    limited_closing_speed,
    pair_reach,
    span,
    speed_for_range,
    start_speeds,
    stop_distance,
)
from swarm_common.scenario.world_check import world_problem

if TYPE_CHECKING:
    from swarm_common.scenario.spec import Scenario

LAG_MARGIN = 2.0  # the loop must stay Hurwitz with the lag this many times slower
NOISE_SIGMAS = 1.0  # ē must cover at least this many RMS of the noise-induced acceleration error
EMA_NOISE_GAIN = math.sqrt(1.0 / 3.0)  # √Σh² of the differenced, low-passed Δv (see (d))


# ---------------------------------------------------------------------------
# (a) start inside the safe set
# ---------------------------------------------------------------------------
def pair_barriers(p: np.ndarray, v: np.ndarray, tau: float, d_safe: float,
                  vertical_scale: float = 1.0) -> np.ndarray:
    """(N, N) h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D² (m²) of positions p, velocities v (N, 3); with
    ``vertical_scale`` κ, of S Δp, S Δv (module docstring)."""
    return barrier(p[:, None, :] - p[None, :, :], v[:, None, :] - v[None, :, :], tau, d_safe,
                   vertical_scale)


def vertical_d_safe(sc: Scenario) -> float:
    """κD (m): the barrier's distance along z, its largest (D when κ = 1)."""
    return sc.controller.dcbf_vertical_scale * sc.controller.d_safe_m


def _kappa_note(sc: Scenario) -> str:
    """The clause naming κ in a message, empty when κ = 1."""
    k = sc.controller.dcbf_vertical_scale
    return f", controller.dcbf_vertical_scale = {k:g}" if k != 1.0 else ""


def start_problem(sc: Scenario) -> str | None:
    """(a): the pair with the lowest h(0) < 0 (or distance < D), named by its keys."""
    c = sc.controller
    p, v = sc.initial_positions(), sc.initial_velocities()
    h = pair_barriers(p, v, c.tau_safe_s, c.d_safe_m, c.dcbf_vertical_scale)
    iu = np.triu_indices(sc.n, 1)
    k = int(np.argmin(h[iu]))
    i, j = int(iu[0][k]), int(iu[1][k])
    if h[i, j] >= 0.0:
        return None
    d = float(np.linalg.norm(p[i] - p[j]))
    closing = -float(np.dot(v[i] - v[j], p[i] - p[j])) / max(d, 1e-12)
    # name the faster of the two: its velocity is the likelier key to fix
    i, j = (i, j) if np.linalg.norm(v[i]) > np.linalg.norm(v[j]) else (j, i)
    return (
        f"agent[{i}].velocity = {v[i].tolist()}: starts outside the safe set, barrier "
        f"h = {h[i, j]:.2f} m² < 0 with agent id {sc.agents[j].id} (agent[{j}].velocity = "
        f"{v[j].tolist()}; {d:.2f} m apart, closing "
        f"at {closing:.2f} m/s; controller.tau_safe_s = {c.tau_safe_s:g}, "
        f"controller.d_safe_m = {c.d_safe_m:g}{_kappa_note(sc)}): no filter can keep h ≥ 0 "
        "from there"
    )


# ---------------------------------------------------------------------------
# speeds the scenario allows
# ---------------------------------------------------------------------------
def loop_coefficients(sc: Scenario) -> tuple[float, float, float, float]:
    """(c1, c0) of the followers' and (c1, c0) of the leaders' closed loops (1/s, 1/s²)."""
    c = sc.controller
    return (c.clf_lambda + c.ks, c.ks * c.clf_lambda + c.kp / c.kd, c.leader_kd, c.leader_kp)


def trajectory_speed(sc: Scenario) -> float:
    """Peak speed (m/s) the leaders' reference asks of every agent: ‖A‖ω of the sinusoid,
    ``mission.max_speed_mps`` with a [mission], ``lifecycle.climb_rate_mps`` on take-off."""
    lt = sc.leader_trajectory
    v = float(np.linalg.norm(lt.amplitude_m)) * 2.0 * math.pi * lt.frequency_hz
    if sc.mission is not None:
        v = max(v, sc.mission.max_speed_mps)
    if sc.lifecycle.start is StartMode.GROUND:
        v = max(v, sc.lifecycle.climb_rate_mps)
    return v


def start_closing_speed(sc: Scenario) -> float:
    """v̄ (m/s) of the pairs in range from the start: the largest initial relative speed of
    a pair plus the reference's peak speed. The reference motion is common to every agent
    (the bearing Laplacian annihilates translations,
    :mod:`swarm_common.scenario.feasibility`), so it closes a pair only while one of them
    lags it: by at most the whole reference speed."""
    v = sc.initial_velocities()
    dv = np.linalg.norm(v[:, None, :] - v[None, :, :], axis=-1)
    return float(dv.max()) + trajectory_speed(sc)


def pairs_enter(sc: Scenario) -> bool:
    """Whether pairs can come into sensing range in flight: the range is below the
    agents' span (:func:`swarm_common.scenario.transient_check.span`)."""
    return sc.formation.sensing_range_m < span(sc)


def closing_speed(sc: Scenario) -> float:
    """v̄ (m/s): :func:`start_closing_speed`, or, where pairs come into range in flight and
    ``controller.max_transient_speed_mps`` = v_t > 0 bounds the followers' transient, the
    larger of it and :func:`~swarm_common.scenario.transient_check.limited_closing_speed`.
    With v_t = 0 such pairs close at a speed nothing bounds: (b) refuses the scenario
    (:func:`transient_problem`), and this is the start's v̄."""
    v_bar = start_closing_speed(sc)
    v_t = sc.controller.max_transient_speed_mps
    if v_t <= 0.0 or not pairs_enter(sc):
        return v_bar
    s_f, s_l = start_speeds(sc)
    return max(v_bar, limited_closing_speed(v_t, trajectory_speed(sc), s_f, s_l))


# ---------------------------------------------------------------------------
# (b) sensing range vs braking distance
# ---------------------------------------------------------------------------
def braking_accel(sc: Scenario) -> float:
    """a_b (m/s²): the horizontal authority at hover, less the disturbance (see (b))."""
    lim = InputSet.of(sc.vehicle, sc.controller)
    return float(lim.horizontal(np.zeros(1))[0]) - sc.disturbance.amplitude_n / sc.vehicle.mass_kg


def entry_range(sc: Scenario, v_bar: float) -> float:
    """R_h (m): the distance at which a pair closing head-on at v̄ has h = 0, along z
    (where it is largest: with D → κD; S scales distance and speed alike)."""
    return entry_distance(v_bar, sc.controller.tau_safe_s, vertical_d_safe(sc))


def stop_range(sc: Scenario, v_bar: float, a_b: float) -> float:
    """R_b (m): κD + v̄(dt + τ) + v̄²/(2a_b) (stopping before the barrier's distance along
    z), inf when a_b ≤ 0."""
    return stop_distance(v_bar, vertical_d_safe(sc), a_b,
                         sc.control_dt + sc.vehicle.tau_rollpitch_s)


def pair_terms(sc: Scenario) -> tuple[float, float, float, float]:
    """(τ_s, κD, a_b, dt + τ) of (b) for ``sc``: the barrier's horizon (s), its distance
    along z (m), the braking authority (m/s²) and the lag before braking (s)."""
    return (sc.controller.tau_safe_s, vertical_d_safe(sc), braking_accel(sc),
            sc.control_dt + sc.vehicle.tau_rollpitch_s)


def reach_of(sc: Scenario) -> Callable[[float], float]:
    """``reach(v̄)``: max(R_h, R_b) (m) of (b) for a pair of ``sc`` closing at v̄ (m/s), its
    terms computed once (the dcbf follower's rows of heard neighbours call it every step,
    offboard.agent.unsensed)."""
    tau_s, d, a_b, lag = pair_terms(sc)
    return functools.partial(pair_reach, tau_s=tau_s, d=d, a_b=a_b, lag=lag)


def needed_range(sc: Scenario, v_bar: float) -> float:
    """max(R_h, R_b) (m) for a pair closing at ``v_bar`` (m/s)."""
    return reach_of(sc)(v_bar)


def range_speed(sc: Scenario) -> float:
    """v̄_R (m/s): the largest closing speed at which ``formation.sensing_range_m`` keeps
    (b) (:func:`~swarm_common.scenario.transient_check.speed_for_range`)."""
    return speed_for_range(sc.formation.sensing_range_m, *pair_terms(sc))


def allowed_transient_speed(sc: Scenario) -> float:
    """The largest ``controller.max_transient_speed_mps`` (m/s) that the sensing range
    allows (:func:`~swarm_common.scenario.transient_check.largest_transient_speed`); ≤ 0 or
    below the followers' initial speeds when none does."""
    return largest_transient_speed(range_speed(sc), trajectory_speed(sc), start_speeds(sc)[1])


def transient_problem(sc: Scenario) -> str | None:
    """(b) for the pairs that come into range in flight (:func:`pairs_enter`): v_t =
    ``controller.max_transient_speed_mps`` must be > 0 and small enough for the range
    (docs/safety.md §5i)."""
    c, r = sc.controller, sc.formation.sensing_range_m
    rogue = next((k for k, a in enumerate(sc.agents) if not a.cooperative), None)
    if rogue is not None:  # it flies no filter, so no speed row bounds it (§5i)
        reach = max(span(sc), needed_range(sc, start_closing_speed(sc)))
        return (f"agent[{rogue}].cooperative = false: pairs come into range in flight "
                f"(formation.sensing_range_m = {r:g} < the agents' span {span(sc):.2f} m) "
                "and nothing bounds how fast a follower with no filter closes: set the "
                f"range ≥ {reach:.2f} m")
    v_t, ref = c.max_transient_speed_mps, trajectory_speed(sc)
    v_bar = closing_speed(sc)
    need = needed_range(sc, v_bar)
    if v_t > 0.0 and r >= need:
        return None
    s_f = start_speeds(sc)[0]
    v_r = range_speed(sc)
    x = math.floor(100.0 * allowed_transient_speed(sc)) / 100.0
    reach = span(sc)
    y = max(reach, needed_range(sc, start_closing_speed(sc)))  # no pair comes into range
    head = (f"formation.sensing_range_m = {r:g}: pairs come into range in flight (the "
            f"agents span {reach:.2f} m at the start or in the formation)")
    if v_t <= 0.0:
        why = ", and nothing bounds how fast (controller.max_transient_speed_mps = 0)"
    else:
        y = min(y, need)
        why = (f", closing at up to {v_bar:.2f} m/s with controller.max_transient_speed_mps"
               f" = {v_t:g} (the reference {ref:.2f} m/s + {v_bar - ref:.2f} m/s of "
               f"transients), which must be sensed from {need:.2f} m{_kappa_note(sc)}")
    if x > 0.0 and x >= s_f:
        fix = f": set controller.max_transient_speed_mps ≤ {x:.2f} m/s or the range ≥ {y:.2f} m"
    else:
        fix = (f": no controller.max_transient_speed_mps fits (the range allows a closing "
               f"speed of {v_r:.2f} m/s; the reference {ref:.2f} m/s and the initial speeds "
               f"take it): set the range ≥ {y:.2f} m")
    return head + why + fix


def range_problem(sc: Scenario) -> str | None:
    """(b): ``formation.sensing_range_m`` below max(R_h, R_b) at the start's closing speed;
    then, where pairs come into range in flight, :func:`transient_problem`."""
    v_bar = start_closing_speed(sc)
    a_b = braking_accel(sc)
    r_h, r_b = entry_range(sc, v_bar), stop_range(sc, v_bar, a_b)
    need = max(r_h, r_b)
    r = sc.formation.sensing_range_m
    if r >= need:
        return None if not pairs_enter(sc) else transient_problem(sc)
    if a_b <= 0.0:
        return (
            f"disturbance.amplitude_n = {sc.disturbance.amplitude_n:g}: "
            f"{sc.disturbance.amplitude_n / sc.vehicle.mass_kg:.2f} m/s² leaves no horizontal "
            f"authority to brake ({a_b:.2f} m/s² after vehicle.tilt_max_deg = "
            f"{sc.vehicle.tilt_max_deg:g}, controller.u_max_mps2 = {sc.controller.u_max_mps2:g})"
        )
    ref = trajectory_speed(sc)
    source = ("mission.max_speed_mps" if sc.mission is not None
              and ref == sc.mission.max_speed_mps else "the reference")
    return (
        f"formation.sensing_range_m = {r:g}: a pair closing at up to {v_bar:.2f} m/s "
        f"({source} {ref:.2f} m/s + the largest initial relative speed "
        f"{v_bar - ref:.2f} m/s) must be "
        f"sensed from {need:.2f} m (h ≥ 0 there: {r_h:.2f} m; braking at {a_b:.2f} m/s² "
        f"after dt + vehicle.tau_rollpitch_s = {sc.control_dt + sc.vehicle.tau_rollpitch_s:g} s"
        f": {r_b:.2f} m{_kappa_note(sc)})"
    )


# ---------------------------------------------------------------------------
# (c) attitude lag vs the control loop
# ---------------------------------------------------------------------------
def _tau_eff(sc: Scenario) -> float:
    """τ_e = max(τ_rp, τ_F) + dt/2 (s)."""
    return max(sc.vehicle.tau_rollpitch_s, sc.vehicle.tau_thrust_s) + 0.5 * sc.control_dt


def max_lag(c1: float, c0: float, dt: float) -> float:
    """Largest attitude lag τ (s) with τ + dt/2 ≤ c1/(LAG_MARGIN c0)."""
    return c1 / (LAG_MARGIN * c0) - 0.5 * dt


def lag_problem(sc: Scenario) -> str | None:
    """(c): the lag above the bound of the followers' loop or the leaders' PD."""
    c1, c0, l1, l0 = loop_coefficients(sc)
    tau = max(sc.vehicle.tau_rollpitch_s, sc.vehicle.tau_thrust_s)
    key = ("vehicle.tau_rollpitch_s" if sc.vehicle.tau_rollpitch_s >= sc.vehicle.tau_thrust_s
           else "vehicle.tau_thrust_s")
    for who, a1, a0, gains in (
        ("followers' loop", c1, c0, "controller.clf_lambda + ks, ks·clf_lambda + kp/kd"),
        ("leaders' PD", l1, l0, "controller.leader_kd, leader_kp"),
    ):
        bound = max_lag(a1, a0, sc.control_dt)
        if tau <= bound:
            continue
        why = (f"the {who} (c1 = {a1:g}, c0 = {a0:g} from {gains}) keeps a lag margin of "
               f"{LAG_MARGIN:g} (Routh–Hurwitz: τ + dt/2 ≤ c1/({LAG_MARGIN:g} c0))")
        budget = a1 / (LAG_MARGIN * a0)  # τ + dt/2 allowed (s)
        if tau >= budget:  # the lag alone breaks it: no rate helps
            return (f"{key} = {tau:g}: above {budget:.3f} s at any control rate, the lag at "
                    f"which {why}")
        need = f"control_hz >= {1.0 / (2.0 * (budget - tau)):.2f}"
        if bound <= 0.0:  # half a period alone breaks it: the rate's fault
            return (f"scenario.control_hz = {sc.run.control_hz}: half a period "
                    f"({0.5 * sc.control_dt:g} s) plus {key} = {tau:g} exceeds {budget:.3f} s, "
                    f"the lag at which {why}; it needs {need}")
        return (f"{key} = {tau:g}: above {bound:.3f} s, the lag at which {why} at "
                f"scenario.control_hz = {sc.run.control_hz} (or {need})")
    return None


# ---------------------------------------------------------------------------
# (d) noise vs the margin ē
# ---------------------------------------------------------------------------
def noise_accel_rms(sc: Scenario, distance: float) -> float:
    """RMS (m/s²) of the relative-acceleration estimate's noise at ``distance`` (m)."""
    s = sc.sensing
    sig_v = math.sqrt(s.range_rate_noise_mps**2 + 3.0 * (distance * s.bearing_rate_noise_radps)**2)
    return EMA_NOISE_GAIN * sig_v / sc.control_dt


def noise_problem(sc: Scenario) -> str | None:
    """(d): NOISE_SIGMAS × the noise RMS above ``controller.dcbf_accel_error_mps2``, or
    above ``dcbf_trust_error_mps2`` when the trust region is on (its rows' margin for the
    noise, docs/safety.md 5f)."""
    d = entry_range(sc, closing_speed(sc))
    need = NOISE_SIGMAS * noise_accel_rms(sc, d)
    c = sc.controller
    key, e_bar = "dcbf_accel_error_mps2", c.dcbf_accel_error_mps2
    if c.dcbf_trust_jump_mps2 > 0.0:
        key, e_bar = "dcbf_trust_error_mps2", c.dcbf_trust_error_mps2
    if need <= e_bar:
        return None
    s = sc.sensing
    return (
        f"sensing.range_rate_noise_mps = {s.range_rate_noise_mps:g} (bearing_rate_noise_radps"
        f" = {s.bearing_rate_noise_radps:g}): {NOISE_SIGMAS:g} RMS of the relative-"
        f"acceleration noise at {d:.2f} m is {need:.2f} m/s², above the margin "
        f"controller.{key} = {e_bar:g}"
    )


def safety_problems(sc: Scenario) -> list[str]:
    """Every broken load-time assumption of ``sc``, one line each, in the order (a)–(d),
    then the world's (:func:`swarm_common.scenario.world_check.world_problem`)."""
    checks = (start_problem, lag_problem, range_problem, noise_problem, world_problem)
    return [p for p in (check(sc) for check in checks) if p is not None]
