"""Quadrotor swarm dynamics (paper §2.2, §5.1): pure, vectorised over N vehicles, no I/O.

World frame ENU-style, z up (the paper's frame); body FLU; Euler ZYX. Per vehicle::

    m p̈ = R(φ,θ,ψ) [0,0,F]ᵀ − m g e_z + m Φ(p, v) ζ + d(t)

* First-order attitude inner loop: φ̇ = (φ_c − φ)/τ_rp, θ̇ likewise, ψ̇ = (ψ_c − ψ)/τ_ψ,
  Ḟ = (F_c − F)/τ_F. Commanded tilt clamped to ``tilt_max``, thrust to [0, F_max].
  The lags are integrated exactly (zero-order hold of the command over one physics step).
* External disturbance d(t) = A [cos ωt, sin ωt, sin ωt] newtons (§5.1).
* Unmodeled dynamics f̃ = Φ(p, v) ζ in m/s² with the six regressor columns of
  :func:`regressor`; ζ per vehicle = nominal ⊙ (1 + spread·U(−1, 1)), seeded.
* Ground contact: nothing falls through z = 0 (position clamped, downward velocity zeroed).
* Collision event: a pair entering distance < ``collision_radius_m`` (counted on entry).
* With ``held=True`` vehicles stay at their spawn state until released (``release``):
  a spawn fixture, used by the MAVLink simulator until a vehicle is first armed.

Translational state uses semi-implicit Euler at the physics rate (default 200 Hz).
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.fastnp import einsum
from swarm_common.scenario import Scenario
from swarm_common.unmodeled import N_ZETA, regressor  # noqa: F401 (re-exported)


def external_disturbance(t: float, amplitude_n: float, omega: float) -> np.ndarray:
    """d(t) = A [cos ωt, sin ωt, sin ωt] in newtons (paper §5.1)."""
    return amplitude_n * np.array([math.cos(omega * t), math.sin(omega * t), math.sin(omega * t)])


class SwarmDynamics:
    """N quadrotors integrated together at a fixed physics step."""

    def __init__(self, sc: Scenario, seed: int | None = None, held: bool = False) -> None:
        veh = sc.vehicle
        self.n = sc.n
        self.ids = sc.ids
        self.dt = sc.physics_dt
        self.mass = veh.mass_kg
        self.g = veh.gravity_mps2
        self.f_max = veh.thrust_max_n
        self.tilt_max = math.radians(veh.tilt_max_deg)
        self.tau = np.array([veh.tau_rollpitch_s, veh.tau_rollpitch_s, veh.tau_yaw_s])
        self.tau_f = veh.tau_thrust_s
        self.collision_radius = veh.collision_radius_m
        self.dist_amp = sc.disturbance.amplitude_n
        self.dist_omega = sc.disturbance.omega_rad_s
        self.ge_height = sc.unmodeled.ground_effect_height_m
        rng = np.random.default_rng([sc.seed if seed is None else seed, 0xD1])
        nominal = np.array(sc.unmodeled.zeta_nominal, dtype=float)
        spread = sc.unmodeled.zeta_spread
        self.zeta = nominal * (1.0 + spread * rng.uniform(-1.0, 1.0, size=(self.n, N_ZETA)))
        # exact discretisation of the first-order lags over one physics step
        self._a_att = np.exp(-self.dt / self.tau)
        self._a_f = math.exp(-self.dt / self.tau_f)

        self.t = 0.0
        self.step_count = 0
        self.p = sc.initial_positions()
        self.v = sc.initial_velocities()
        self.att = np.zeros((self.n, 3))
        hover = self.mass * self.g
        self.thrust = np.full(self.n, hover)
        self.cmd_att = np.zeros((self.n, 3))
        self.cmd_thrust = np.full(self.n, hover)
        self.held = np.full(self.n, held, dtype=bool)
        self.collisions = 0
        self.collision_pairs: list[tuple[float, int, int]] = []
        self._in_contact = np.zeros((self.n, self.n), dtype=bool)
        self._iu = np.triu_indices(self.n, 1)
        self._step_dist = self.pair_distances()  # of the last step (step_min_distance)

    # -- commands ---------------------------------------------------------------
    def set_command(self, idx: int, roll: float, pitch: float, yaw: float, thrust_n: float) -> None:
        """Commanded attitude (ENU/FLU Euler, rad) and thrust (N) of vehicle ``idx``.

        Non-finite values are ignored (the previous command is kept). Tilt is clamped
        to ``tilt_max`` per axis, thrust to [0, F_max].
        """
        vals = (roll, pitch, yaw, thrust_n)
        if not all(math.isfinite(x) for x in vals):
            return
        lim = self.tilt_max
        self.cmd_att[idx] = (min(lim, max(-lim, roll)), min(lim, max(-lim, pitch)), yaw)
        self.cmd_thrust[idx] = min(self.f_max, max(0.0, thrust_n))

    def release(self, idx: int | None = None) -> None:
        """Let vehicle ``idx`` (or all) leave the spawn fixture with its spawn velocity."""
        if idx is None:
            self.held[:] = False
        else:
            self.held[idx] = False

    def hold_thrust(self) -> float:
        """Thrust (N) that balances gravity."""
        return self.mass * self.g

    # -- integration --------------------------------------------------------------
    def thrust_accel(self) -> np.ndarray:
        """(N,3) acceleration from thrust alone, R e3 F / m."""
        att = self.att
        # one cos and one sin over (N,3): the same values as per column (numpy's
        # elementwise loops do not depend on stride or length; checked bit for bit)
        c, s = np.cos(att), np.sin(att)
        cr, cp, cy = c[:, 0], c[:, 1], c[:, 2]
        sr, sp, sy = s[:, 0], s[:, 1], s[:, 2]
        b3 = np.empty((len(att), 3))  # filled column by column: no np.stack
        b3[:, 0] = cy * sp * cr + sy * sr
        b3[:, 1] = sy * sp * cr - cy * sr
        b3[:, 2] = cp * cr
        b3 *= (self.thrust / self.mass)[:, None]
        return b3

    def virtual_control(self) -> np.ndarray:
        """(N,3) the paper's u = R[0,0,F]/m − g e_z realised by the vehicles."""
        a = self.thrust_accel()
        a[:, 2] -= self.g
        return a

    def lumped_accel(self, t: float | None = None) -> np.ndarray:
        """(N,3) true lumped disturbance Φ(p,v)ζ + d(t)/m (m/s²), what the DESO estimates."""
        tt = self.t if t is None else t
        # Φ(p, v) ζ written out per column (same sum as regressor(...) @ ζ, without
        # building the (N,3,6) array: this runs at every physics step)
        v, z = self.v, self.zeta
        speed = np.sqrt(einsum("ij,ij->i", v, v))[:, None]
        f = z[:, 0:1] - (z[:, 1:2] + z[:, 2:3] * speed) * v - z[:, 3:4] * v**3
        f[:, 2] += z[:, 4] * np.exp(-np.maximum(self.p[:, 2], 0.0) / self.ge_height)
        f[:, 0] -= z[:, 5] * v[:, 1]
        f[:, 1] += z[:, 5] * v[:, 0]
        # d(t)/m of external_disturbance, in plain floats: the same roundings
        # ((A·cos ωt)/m per component) without building two small arrays
        amp, m, wt = self.dist_amp, self.mass, self.dist_omega * tt
        dc, ds = amp * math.cos(wt) / m, amp * math.sin(wt) / m
        f += (dc, ds, ds)
        return f

    def step(self) -> None:
        """Advance one physics step of ``dt``."""
        dt = self.dt
        cmd_att, cmd_thrust = self.cmd_att, self.cmd_thrust
        self.att = cmd_att + (self.att - cmd_att) * self._a_att
        self.thrust = cmd_thrust + (self.thrust - cmd_thrust) * self._a_f
        acc = self.virtual_control()
        acc += self.lumped_accel()
        acc *= dt
        v_new = self.v + acc
        p_new = v_new * dt
        p_new += self.p
        ground = p_new[:, 2] < 0.0
        if ground.any():
            p_new[ground, 2] = 0.0
            v_new[ground, 2] = np.maximum(v_new[ground, 2], 0.0)
            v_new[ground, :2] *= 0.0  # friction: a landed vehicle stops
        held = self.held
        if held.any():
            free = ~held
            self.v = np.where(free[:, None], v_new, self.v)
            self.p = np.where(free[:, None], p_new, self.p)
        else:
            self.v, self.p = v_new, p_new
        self.t = (self.step_count + 1) * dt
        self.step_count += 1
        self._update_collisions()

    def advance(self, n_steps: int) -> None:
        for _ in range(n_steps):
            self.step()

    # -- geometry -----------------------------------------------------------------
    def pair_distances(self) -> np.ndarray:
        """(N,N) distance matrix of true positions (np.linalg.norm(d, axis=-1)'s own
        arithmetic, without its dispatch)."""
        p = self.p
        d = p[:, None, :] - p[None, :, :]
        d *= d
        return np.sqrt(np.add.reduce(d, axis=-1))

    def min_pair_distance(self) -> float:
        return float(self.pair_distances()[self._iu].min())

    def step_min_distance(self) -> float:
        """:meth:`min_pair_distance` right after :meth:`step`, from the distances its
        collision check computed (not recomputed: call it before p changes again)."""
        return float(self._step_dist[self._iu].min())

    def _update_collisions(self) -> None:
        dist = self.pair_distances()
        self._step_dist = dist
        contact = dist < self.collision_radius
        np.fill_diagonal(contact, False)
        new = contact & ~self._in_contact
        if new.any():
            for i, j in zip(*np.nonzero(np.triu(new, 1)), strict=True):
                self.collisions += 1
                self.collision_pairs.append((self.t, self.ids[i], self.ids[j]))
        self._in_contact = contact

    def on_ground(self) -> np.ndarray:
        return self.p[:, 2] <= 1e-6
