"""Feasibility of a scenario at load time: can every vehicle fly its desired trajectory
inside the input set it can realise? Pure (no I/O); derivation in docs/scenarios.md.

Desired motion. Every leader flies ``p_L(t) = p_L(0) + A(1 − cos ωt)`` (ω = 2πf) from its
origin (``position``; for a ground start its staging point above the pad, as
:mod:`offboard.agent.takeoff` plans it). Every follower's target is the bearing-formation
solution ``p*_f = −L_ff⁻¹ L_fl p_L`` (paper §2.1). The bearing Laplacian annihilates
translations (``L(1⊗δ) = 0``), so a common leader offset δ(t) moves every target by the
same δ(t): ``p*_i(t) = p*_i(0) + A(1 − cos ωt)`` for every agent i, with the same
acceleration ``a(t) = Aω² cos ωt`` (peak ‖A‖ω²) and jerk ``j(t) = −Aω³ sin ωt``.

Needed command. Through the inner loop ``ȧ = (u − a)/τ`` (τ_rp horizontally, τ_F
vertically) the command that tracks a(t) exactly is ``u_ff = a + τ ȧ``. On top of it the
controller must cancel the disturbance (per axis at most ``amplitude_n/m``, horizontally
exactly ``amplitude_n/m`` in norm) and the unmodeled dynamics ``f̃ = Φ(p*, v*) ζ`` with every
|ζ_k| up to ``|ζ_nom,k| (1 + zeta_spread)``; their bound ``e`` is added to ``|u_ff|``.

Input set (the dcbf polytope, :class:`swarm_common.scenario.input_set.InputSet`):
``u_z ∈ [−min(u_max, 0.9g), min(u_max, (F_max/m) cos θ − g)]`` and
``‖u_h‖ ≤ (g + u_z) tan θ cos(π/K)``, capped at ``u_max``. A share :data:`FEEDBACK_RESERVE`
of it is kept for feedback: the need must lie in the set scaled by ``1 − r`` about hover
(u = 0). Sampled at :data:`PHASE_SAMPLES` phases of
one period, per agent.

Reachability. A desired position below the ground clearance ``controller.d_safe_m`` at any
time of the trajectory (``min_t z = z(0) + min(0, 2A_z)``) is unreachable.

Control rate (:func:`rate_problem`). Per axis the nominal loop closes e1 = p − p* with
``u = −c1 ė1 − c0 e1`` (followers: c1 = λ + k_s, c0 = k_s λ + k_p/k_d; leaders' PD: c1 =
leader_kd, c0 = leader_kp), sampled every dt = 1/``control_hz`` and held (zero-order hold)
through the lag ``ȧ = (u − a)/τ``. Exactly discretised, the state x = (e1, ė1, a) moves
by ``x⁺ = (Φ − Γ K) x`` with ``[Φ Γ; 0 1] = exp([A B; 0 0] dt)``; a spectral radius ≥ 1
means the loop diverges whatever the gains of the filter on top (measured in
docs/safety.md, "Load-time checks": cube8 at 1, 2 and 4 Hz).

Deadline (:func:`deadline_problem`). The tracking metrics are taken over
[``formation_deadline_s``, end]: a deadline at or after the end leaves them empty.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.linalg import expm

from swarm_common.enums import StartMode
from swarm_common.memo import IdentityMemo
from swarm_common.scenario import graphs, spectra
from swarm_common.scenario.input_set import InputSet
from swarm_common.unmodeled import regressor

if TYPE_CHECKING:
    from swarm_common.scenario.spec import Scenario

FEEDBACK_RESERVE = 0.2  # share of the input set kept for feedback (1 − r scales the set)
PHASE_SAMPLES = 180  # samples of ωt over one period (2°: sampled peaks within 2e-4)


# ---------------------------------------------------------------------------
# Desired motion
# ---------------------------------------------------------------------------
def formation_map(sc: Scenario) -> np.ndarray | None:
    """K = −L_ff⁻¹ L_fl (3F × 3L, scenario order of followers and leaders) with
    ``p*_f = K p_L`` (paper §2.1) over the scenario's neighbour graph (any
    ``formation.graph`` kind, :mod:`swarm_common.scenario.graphs`); None when the graph cannot be
    built or L_ff is singular (the leaders do not fix the followers; the loader refuses
    such a scenario before this check, :func:`swarm_common.scenario.model.graph_problem`)."""
    v = sc.vertices()
    lead = [sc.index_of(i) for i in sc.leader_ids]
    foll = [sc.index_of(i) for i in sc.follower_ids]
    spec = graphs.graph_spec(sc.formation, sc.initial_positions(), v, lead)
    try:
        edges = graphs.build_edges(v, spec, sc.ids)
    except ValueError:
        return None
    lap = graphs.sparse_laplacian(v, edges)
    fb, lb = graphs.blocks(foll), graphs.blocks(lead)
    if not len(fb):
        return np.zeros((0, len(lb)))
    l_ff_s = lap[fb][:, fb]
    if l_ff_s.shape[0] > spectra.DENSE_SPECTRUM_MAX:  # sparse, once per scenario object
        return _sparse_maps.get(sc, "map", lambda: _sparse_map(l_ff_s, lap[fb][:, lb]))
    l_ff = l_ff_s.toarray()
    try:
        chol = np.linalg.cholesky(l_ff)
    except np.linalg.LinAlgError:
        return None
    if np.min(np.abs(np.diag(chol))) ** 2 <= spectra.zero_tol(l_ff_s):
        return None
    return spectra.leader_map(l_ff, lap[fb][:, lb].toarray())


# the sparse maps of large formations: the loader's check, the leaders' governors and the
# preflight check ask for the same one (the dense path is not kept: it is computed under
# whatever BLAS threads its caller has, and the in-process runner's bits are its own)
_sparse_maps: IdentityMemo[np.ndarray | None] = IdentityMemo(4)


def _sparse_map(l_ff: sp.spmatrix, l_fl: sp.spmatrix) -> np.ndarray | None:
    """:func:`formation_map` of a large formation: None when L_ff's smallest eigenvalue
    is zero to :func:`spectra.zero_tol`, else the sparse LU's −L_ff⁻¹ L_fl."""
    if spectra.smallest_eig(l_ff) <= spectra.zero_tol(l_ff):
        return None
    return spectra.leader_map(l_ff, l_fl)


def leader_origins(sc: Scenario) -> np.ndarray:
    """(L, 3) p_L(0) of the leaders (scenario order): ``position``, or for a ground start
    the staging point above the pad at ``takeoff_altitude_m + s (v_z − min v_z)`` (s = pad
    separation over vertex separation of the first two leaders; offboard.agent.takeoff)."""
    pos = sc.initial_positions()
    lead = [sc.index_of(i) for i in sc.leader_ids]
    out = pos[lead].copy()
    if sc.lifecycle.start is StartMode.GROUND:
        v = sc.vertices()
        k1, k2 = (sc.index_of(i) for i in sc.formation.leaders[:2])
        s = float(np.linalg.norm(pos[k1] - pos[k2]) / np.linalg.norm(v[k1] - v[k2]))
        out[:, 2] = sc.lifecycle.takeoff_altitude_m + s * (v[lead, 2] - v[:, 2].min())
    return out


def desired_origins(sc: Scenario) -> np.ndarray | None:
    """(N, 3) p*_i(0) of every agent (scenario order) at the start of the leaders'
    trajectory; None when the formation does not fix the followers (:func:`formation_map`)."""
    kmap = formation_map(sc)
    if kmap is None:
        return None
    out = np.zeros((sc.n, 3))
    lp = leader_origins(sc)
    out[[sc.index_of(i) for i in sc.leader_ids]] = lp
    out[[sc.index_of(i) for i in sc.follower_ids]] = (kmap @ lp.reshape(-1)).reshape(-1, 3)
    return out


def peak_acceleration(sc: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis peak desired acceleration |A|ω² (m/s²) and jerk |A|ω³ (m/s³), the same for
    every agent (module docstring)."""
    lt = sc.leader_trajectory
    w = 2.0 * math.pi * lt.frequency_hz
    amp = np.abs(np.array(lt.amplitude_m))
    return amp * w * w, amp * w**3


# ---------------------------------------------------------------------------
# Checks
# ---------------------------------------------------------------------------
def _fmt(x: tuple[float, ...]) -> str:
    return "[" + ", ".join(f"{v:g}" for v in x) + "]"


def clearance_problem(sc: Scenario, origins: np.ndarray, idx: list[int]) -> str | None:
    """One line naming the key if the desired position of an agent in ``idx`` (origins
    (N, 3) as :func:`desired_origins`) goes below ``d_safe_m`` (the ground clearance) at any
    time of the trajectory, leaders first; else None."""
    clear = sc.controller.d_safe_m
    az = sc.leader_trajectory.amplitude_m[2]
    zmin = origins[:, 2] + min(0.0, 2.0 * az)
    lead = [sc.index_of(i) for i in sc.leader_ids]
    for k in sorted(idx, key=lambda k: k not in lead):
        if zmin[k] >= clear:
            continue
        a = sc.agents[k]
        tail = (f"goes down to z = {zmin[k]:.2f} m (leader_trajectory.amplitude_m z = {az:g}), "
                f"below the ground clearance controller.d_safe_m = {clear:g}")
        if k not in lead:
            return (f"agent[{k}].vertex = {_fmt(tuple(a.vertex))}: follower id {a.id}'s "
                    f"desired position in the formation {tail}")
        if sc.lifecycle.start is StartMode.GROUND:
            return (f"lifecycle.takeoff_altitude_m = {sc.lifecycle.takeoff_altitude_m:g}: "
                    f"leader id {a.id}'s trajectory from its staging point {tail}")
        return (f"agent[{k}].position = {_fmt(tuple(a.position))}: leader id {a.id}'s "
                f"trajectory {tail}")
    return None


def _uncertainty(sc: Scenario, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, ...]:
    """Bounds (m/s²) on what the controller must cancel at desired states p, v (..., 3):
    horizontal norm and vertical, disturbance and unmodeled parts separately."""
    d = sc.disturbance.amplitude_n / sc.vehicle.mass_kg
    um = sc.unmodeled
    zeta = np.abs(np.array(um.zeta_nominal)) * (1.0 + um.zeta_spread)
    f = np.abs(regressor(p, v, um.ground_effect_height_m)) @ zeta  # (..., 3)
    return np.full(f.shape[:-1], d), np.linalg.norm(f[..., :2], axis=-1), f[..., 2]


def acceleration_problem(sc: Scenario, origins: np.ndarray, idx: list[int]) -> str | None:
    """One line naming the key and the numbers if the needed command of an agent in ``idx``
    leaves the input set kept after the feedback reserve at some phase of the trajectory;
    else None."""
    lt, veh = sc.leader_trajectory, sc.vehicle
    w = 2.0 * math.pi * lt.frequency_hz
    amp = np.array(lt.amplitude_m)
    ph = 2.0 * math.pi * np.arange(PHASE_SAMPLES) / PHASE_SAMPLES
    c, s = np.cos(ph)[:, None], np.sin(ph)[:, None]
    tau = np.array([veh.tau_rollpitch_s, veh.tau_rollpitch_s, veh.tau_thrust_s])
    u = amp * w * w * c - tau * amp * w**3 * s  # (M, 3): u_ff = a + τ ȧ
    p = origins[None, idx, :] + (amp * (1.0 - c))[:, None, :]  # (M, n, 3)
    vel = np.broadcast_to((amp * w * s)[:, None, :], p.shape)
    e_d, e_fh, e_fz = _uncertainty(sc, p, vel)
    e_h, e_z = e_d + e_fh, e_d + e_fz  # (M, N)
    lim = InputSet.of(sc.vehicle, sc.controller)
    k = 1.0 - FEEDBACK_RESERVE
    uz, uh = u[:, 2:3], np.linalg.norm(u[:, :2], axis=1)[:, None]
    shape = e_h.shape
    checks = (  # (name, need, allowed, trajectory part) each (M, n)
        ("upward", uz + e_z, np.full(shape, k * lim.uz_max), np.broadcast_to(uz, shape)),
        ("downward", e_z - uz, np.full(shape, -k * lim.uz_min), np.broadcast_to(-uz, shape)),
        ("horizontally", uh + e_h, lim.horizontal(uz - e_z, FEEDBACK_RESERVE),
         np.broadcast_to(uh, shape)),
    )  # vertical first: within them the horizontal allowance is > 0
    for name, need, allowed, traj in checks:
        over = need - allowed
        m, n = np.unravel_index(int(np.argmax(over)), over.shape)
        if over[m, n] <= 0.0:
            continue
        e = float(need[m, n] - traj[m, n])
        if traj[m, n] >= e:
            key = (f"leader_trajectory.frequency_hz = {lt.frequency_hz:g} "
                   f"(amplitude_m = {_fmt(lt.amplitude_m)})")
        elif e_d[m, n] >= e - e_d[m, n]:
            key = f"disturbance.amplitude_n = {sc.disturbance.amplitude_n:g}"
        else:
            key = f"unmodeled.zeta_nominal = {_fmt(sc.unmodeled.zeta_nominal)}"
        t = float(ph[m] / w) if w > 0.0 else 0.0
        return (
            f"{key}: agent id {sc.agents[idx[n]].id} needs {need[m, n]:.2f} m/s² {name} at "
            f"t = {t:.2f} s of the trajectory ({traj[m, n]:.2f} to fly it through the "
            f"inner-loop lag, {e:.2f} to cancel disturbance and unmodeled dynamics), the "
            f"input set allows {allowed[m, n]:.2f} m/s² (vehicle.tilt_max_deg = "
            f"{veh.tilt_max_deg:g}, vehicle.thrust_max_n = {veh.thrust_max_n:g}, "
            f"controller.u_max_mps2 = {sc.controller.u_max_mps2:g}, "
            f"{FEEDBACK_RESERVE:.0%} kept for feedback)"
        )
    return None


RATE_BISECTIONS = 40  # halvings of the control period in :func:`min_control_hz` (1e-12 relative)
MAX_RATE_HZ = 1e4  # search ceiling of :func:`min_control_hz` (Hz)


def sampled_loop_radius(c1: float, c0: float, tau: float, dt: float) -> float:
    """Spectral radius of one period of the sampled loop (module docstring, "Control
    rate"): gains c1 (1/s), c0 (1/s²), lag τ (s), period dt (s); < 1 ⇔ it converges."""
    m = np.zeros((4, 4))
    m[0, 1] = m[1, 2] = 1.0
    m[2, 2], m[2, 3] = -1.0 / tau, 1.0 / tau
    e = expm(m * dt)
    closed = e[:3, :3] - np.outer(e[:3, 3], [c0, c1, 0.0])
    return float(np.max(np.abs(np.linalg.eigvals(closed))))


def min_control_hz(c1: float, c0: float, tau: float, hz: float) -> float:
    """The lowest control rate (Hz) above which the sampled loop converges, found by
    bisection between ``hz`` (where it diverges) and a rate where it converges (None of
    them up to :data:`MAX_RATE_HZ`: that ceiling)."""
    lo, hi = hz, 2.0 * hz
    while sampled_loop_radius(c1, c0, tau, 1.0 / hi) >= 1.0:
        lo, hi = hi, 2.0 * hi
        if hi > MAX_RATE_HZ:
            return MAX_RATE_HZ
    for _ in range(RATE_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if sampled_loop_radius(c1, c0, tau, 1.0 / mid) >= 1.0:
            lo = mid
        else:
            hi = mid
    return hi


def rate_problem(sc: Scenario) -> str | None:
    """One line naming ``scenario.control_hz`` if a sampled loop (followers' or leaders',
    horizontal with τ_rp or vertical with τ_F) diverges at that rate while a faster one
    would converge (τ c0 < c1, Routh–Hurwitz of the continuous loop); else None. A lag
    that no rate can carry is :func:`swarm_common.scenario.safety_check.lag_problem`'s."""
    c = sc.controller
    hz = float(sc.run.control_hz)
    veh = sc.vehicle
    for who, c1, c0, gains in (
        ("followers'", c.clf_lambda + c.ks, c.ks * c.clf_lambda + c.kp / c.kd,
         "controller.clf_lambda + ks, ks·clf_lambda + kp/kd"),
        ("leaders'", c.leader_kd, c.leader_kp, "controller.leader_kd, leader_kp"),
    ):
        for axis, key, tau in (("horizontal", "vehicle.tau_rollpitch_s", veh.tau_rollpitch_s),
                               ("vertical", "vehicle.tau_thrust_s", veh.tau_thrust_s)):
            if tau * c0 >= c1:  # not Hurwitz however fast it samples: the lag's fault,
                continue  # refused by safety_check.lag_problem (it names the lag)
            rho = sampled_loop_radius(c1, c0, tau, 1.0 / hz)
            if rho < 1.0:
                continue
            need = min_control_hz(c1, c0, tau, hz)
            return (
                f"scenario.control_hz = {sc.run.control_hz}: the {who} {axis} loop (c1 = "
                f"{c1:g}, c0 = {c0:g} from {gains}; {key} = {tau:g}) sampled every "
                f"{1.0 / hz:g} s has spectral radius {rho:.3f} >= 1 and diverges; it "
                f"needs control_hz above {need:.2f}"
            )
    return None


def deadline_problem(deadline_s: float, duration_s: float, source: str) -> str | None:
    """One line naming both times if the tracking window [``deadline_s``, ``duration_s``]
    is empty (``source``: where the duration comes from, e.g. ``scenario.duration_s`` or
    ``--duration``); else None."""
    if deadline_s < duration_s:
        return None
    return (
        f"scenario.formation_deadline_s = {deadline_s:g}: not before the end of the run "
        f"({source} = {duration_s:g} s), so the tracking metrics would be empty"
    )


def feasibility_problem(sc: Scenario) -> str | None:
    """The first feasibility problem of ``sc`` as one line naming the key and the numbers
    (no file name), or None when it is feasible: the control rate (:func:`rate_problem`),
    the deadline (:func:`deadline_problem`), then the trajectory. Followers are skipped when
    the formation does not fix them (:func:`formation_map`); only the leaders are checked
    then."""
    problem = rate_problem(sc) or deadline_problem(
        sc.run.formation_deadline_s, sc.run.duration_s, "scenario.duration_s")
    if problem is not None:
        return problem
    origins = desired_origins(sc)
    idx = list(range(sc.n))
    if origins is None:
        idx = [sc.index_of(i) for i in sc.leader_ids]
        origins = np.zeros((sc.n, 3))
        origins[idx] = leader_origins(sc)
    return clearance_problem(sc, origins, idx) or acceleration_problem(sc, origins, idx)
