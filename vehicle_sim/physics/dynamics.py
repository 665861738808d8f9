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
The step is compiled (:mod:`vehicle_sim.physics.dynamics_kernel`); this class keeps the state,
the commands, the seeded ζ and the collision record.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_common.fastnp import bools, f64
from swarm_common.jit import CallSite
from swarm_common.scenario.model import Scenario
from swarm_common.unmodeled import N_ZETA, regressor  # noqa: F401 (re-exported)
from vehicle_sim.physics.contacts_kernel import (
    GRID_MIN,
    min_upper_kernel,
    pair_distances_kernel,
)
from vehicle_sim.physics.dynamics_kernel import (
    lumped_accel_kernel,
    set_command_kernel,
    set_commands_kernel,
    steps_kernel,
    thrust_accel_kernel,
)


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
        self._contact_count = np.zeros(1, dtype=np.int64)  # pairs in _in_contact
        self._iu = np.triu_indices(self.n, 1)
        # the last step's distance matrix, kept up to GRID_MIN vehicles; a larger swarm's
        # step finds its contacts on a grid, without one (contacts_kernel.contacts_into)
        dist = self.pair_distances()
        self._step_min = min_upper_kernel(dist)  # the last step's minimum (m)
        self._step_dist = dist if self.n <= GRID_MIN else np.zeros((0, 0))
        # the pairs entering contact in a period's sub-steps and the sub-step of each
        # (advance_period writes the first rows)
        self._period_pairs = np.zeros((0, 2), dtype=np.int64)
        self._period_pair_step = np.zeros(0, dtype=np.int64)
        # the per-period kernels' call sites: every array argument is guarded or is the
        # model's own buffer (tests and the server assign the state arrays and flags;
        # a scalar of another type is converted by the entry point itself)
        self._steps = CallSite(steps_kernel)
        self._set_command = CallSite(set_command_kernel)
        self._set_commands = CallSite(set_commands_kernel)
        self._lumped = CallSite(lumped_accel_kernel)

    # -- commands ---------------------------------------------------------------
    def set_command(self, idx: int, roll: float, pitch: float, yaw: float, thrust_n: float) -> None:
        """Commanded attitude (ENU/FLU Euler, rad) and thrust (N) of vehicle ``idx``.

        Non-finite values are ignored (the previous command is kept). Tilt is clamped
        to ``tilt_max`` per axis, thrust to [0, F_max] (compiled:
        :func:`vehicle_sim.physics.dynamics_kernel.set_command_kernel`).
        """
        self._set_command.call(self.cmd_att, self.cmd_thrust, int(idx), float(roll),
                               float(pitch), float(yaw), float(thrust_n),
                               float(self.tilt_max), float(self.f_max))

    def set_commands(
        self, roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray, thrust_n: np.ndarray
    ) -> None:
        """:meth:`set_command` of every vehicle at once, (N,) arrays in scenario order (one
        compiled call: :func:`vehicle_sim.physics.dynamics_kernel.set_commands_kernel`)."""
        self._set_commands.call(self.cmd_att, self.cmd_thrust, f64(roll), f64(pitch),
                                f64(yaw), f64(thrust_n), float(self.tilt_max),
                                float(self.f_max))

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
        """(N,3) acceleration from thrust alone, R e3 F / m (m/s²; compiled:
        :func:`vehicle_sim.physics.dynamics_kernel.thrust_accel_kernel`)."""
        return thrust_accel_kernel(f64(self.att), f64(self.thrust), self.mass)

    def virtual_control(self) -> np.ndarray:
        """(N,3) the paper's u = R[0,0,F]/m − g e_z realised by the vehicles (m/s²)."""
        a = self.thrust_accel()
        a[:, 2] -= self.g
        return a

    def lumped_accel(self, t: float | None = None) -> np.ndarray:
        """(N,3) true lumped disturbance Φ(p,v)ζ + d(t)/m (m/s²), what the DESO estimates
        (compiled: :func:`vehicle_sim.physics.dynamics_kernel.lumped_accel_kernel`)."""
        tt = self.t if t is None else t
        return self._lumped.call(
            f64(self.p), f64(self.v), f64(self.zeta), self.ge_height, self.dist_amp,
            self.mass, self.dist_omega, float(tt),
        )

    def step(self) -> None:
        """Advance one physics step of ``dt``: :meth:`advance_period` of one step (compiled:
        :func:`vehicle_sim.physics.dynamics_kernel.step_kernel`, through ``steps_kernel``), so a
        single step and a period's sub-steps share one path and one collision record."""
        self.advance_period(1)

    def advance(self, n_steps: int) -> None:
        for _ in range(n_steps):
            self.step()

    def advance_period(self, n_steps: int) -> float:
        """``n_steps`` ≥ 1 calls of :meth:`step` in one compiled call (the sub-steps of a
        control period, the commands held:
        :func:`~vehicle_sim.physics.dynamics_kernel.steps_kernel`),
        to the same bits. Returns the minimum pair distance over the sub-steps (m; +inf
        for N < 2), the ``min`` of :meth:`step_min_distance` after each."""
        n_steps = int(n_steps)
        if n_steps < 1:
            raise ValueError(f"advance_period: n_steps {n_steps} < 1")
        rows = n_steps * (self.n * (self.n - 1) // 2)
        if self._period_pairs.shape[0] < rows:
            self._period_pairs = np.zeros((rows, 2), dtype=np.int64)
            self._period_pair_step = np.zeros(rows, dtype=np.int64)
        # the contacts and distances, which the kernel writes in place, and the held flags
        # made its types here and kept (a copy converted in the call would take the writes)
        self._in_contact = bools(self._in_contact)
        self._step_dist = f64(self._step_dist)
        self.held = bools(self.held)
        p, v, att, thrust, n_new, md, dmin = self._steps.call(
            f64(self.p), f64(self.v), f64(self.att), f64(self.thrust),
            f64(self.cmd_att), f64(self.cmd_thrust), self.held, f64(self.zeta), self._a_att,
            self._a_f, self.mass, self.g, self.dt, self.ge_height, self.dist_amp,
            self.dist_omega, float(self.t), int(self.step_count), n_steps, self._in_contact,
            self.collision_radius, self._step_dist, self._period_pairs,
            self._period_pair_step, self._contact_count,
        )
        self.p, self.v, self.att, self.thrust = p, v, att, thrust
        first = self.step_count
        self.step_count += n_steps
        self.t = self.step_count * self.dt
        self._step_min = dmin
        steps = self._period_pair_step[:n_new].tolist()
        for (i, j), s in zip(self._period_pairs[:n_new].tolist(), steps, strict=True):
            self.collisions += 1
            self.collision_pairs.append(((first + s + 1) * self.dt, self.ids[i], self.ids[j]))
        return md

    # -- geometry -----------------------------------------------------------------
    def pair_distances(self) -> np.ndarray:
        """(N,N) distance matrix of true positions (m; the arithmetic of
        np.linalg.norm(d, axis=-1), compiled)."""
        return pair_distances_kernel(f64(self.p))

    def min_pair_distance(self) -> float:
        return float(self.pair_distances()[self._iu].min())

    def step_min_distance(self) -> float:
        """:meth:`min_pair_distance` right after :meth:`step`, from the distances its
        collision check computed (not recomputed: call it before p changes again)."""
        if self.n < 2:
            return float(self.pair_distances()[self._iu].min())  # numpy's error, as before
        return self._step_min

    def on_ground(self) -> np.ndarray:
        return self.p[:, 2] <= 1e-6
