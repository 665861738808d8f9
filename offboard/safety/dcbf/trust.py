"""The dcbf filter's trust region: a margin ē that depends on the command jump
(docs/safety.md, "Dense formations: liveness"). Opt-in per scenario
(``controller.dcbf_trust_jump_mps2`` > 0).

The margin ē of the barrier rows (assumption A3) bounds, among other errors, the error of
the per-axis lag model the rows predict the own acceleration with. That error grows with
the command jump ``u − a0`` (a0 the realised acceleration the prediction starts from) and
with the tilt at a0 (the thrust lag then moves the horizontal acceleration too). A single
ē large enough for every jump (cube8: 2 m/s²) keeps two hovering agents 2.75 m apart; the
trust region instead bounds the jump: the tight QP takes ``‖u − a0‖∞ ≤ J`` as hard rows,
and its barrier rows carry

    ē(J, a0) = ē_base + ē_model(J, b(a0))

with ē_base = ``dcbf_trust_error_mps2`` (the rest of A3: noise, estimate errors, the other
agent's deviation from its assumed acceleration) and ē_model the lag model's error for
jumps inside the box J from any a0 with ``‖a0‖∞ ≤ b``, b the smallest of :data:`A0_BINS`
that holds a0 (:func:`model_error_table`, measured on the scenario's own vehicle model
the first time a bound is used). The own part of A3 is then a measured bound that the QP
enforces, not an assumption. J is chosen per step (:meth:`TrustRegion.level`). When the
margin would reach the full one, or the tight QP needs its slack σ > 0, the step falls
back to the full-ē rows of today's QP
(:meth:`offboard.safety.dcbf.filter.DcbfFilter.solve_rows`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from offboard.inner_loop.attitude import InnerLoopModel, setpoint_from_accel
from offboard.safety.dcbf.model import LagCoefficients, ProjectedInputSet
from swarm_common.scenario.model import VehicleConfig

# ‖a0‖∞ (m/s²) of the realised acceleration: the bins of the model-error table; beyond
# the last one the tight QP is not tried
A0_BINS = (0.5, 1.0, 2.0, 4.0, 8.0)
LEVELS = 4  # the trust region's bounds J, 2J, 4J, 8J (TrustRegion.level)
ESCALATE = 1.5  # a step's bound is at least this times the previous command's jump
GRID_POINTS = 5  # a0 samples per axis of each bin's cube [−b, b]³
SUB_STEPS = 170  # sub-steps of the real inner-loop model over the horizon (1 ms at 0.17 s)
# the largest error on the grid times this: the worst case between grid points (random
# a0, u checked in tests/unit/safety/test_dcbf_trust.py stay below the grid's maximum)
SAMPLING_FACTOR = 1.2
# the jump directions: the box's 8 corners, 12 edge midpoints and 6 face centres
JUMP_DIRS = np.array([d for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)])


def lag_model_error(
    a0: np.ndarray, u: np.ndarray, veh: VehicleConfig, lag: LagCoefficients,
    n_sub: int = SUB_STEPS,
) -> float:
    """The error (m/s²) of the per-axis lag prediction of :class:`LagCoefficients` against
    the real inner-loop model (:class:`~offboard.inner_loop.attitude.InnerLoopModel`: first-order
    attitude and thrust lags, the nonlinear map to acceleration) over the horizon ``lag.T``,
    from realised acceleration ``a0`` with ``u`` held (both (3,), m/s², yaw 0).

    It is the norm of the constant acceleration error that would explain the worst of
    the three prediction errors: ``max(‖δa‖, ‖δv‖/T, 2‖δp‖/T²)``, the measure of A3
    (docs/safety.md §2: an error ē moves Δp̂ by ēT²/2, Δv̂ by ēT and Δâ by ē)."""
    t = lag.T
    inner = InnerLoopModel(veh, t / n_sub)
    sp0 = setpoint_from_accel(a0, 0.0, veh)
    inner.state = np.array([sp0.roll, sp0.pitch, 0.0, sp0.thrust_n])
    rows = inner.run(setpoint_from_accel(u, 0.0, veh), n_sub)
    acc = np.vstack([a0[None, :], rows])
    h = t / n_sub
    vel = np.vstack([np.zeros((1, 3)), np.cumsum(0.5 * (acc[1:] + acc[:-1]) * h, axis=0)])
    pos = np.sum(0.5 * (vel[1:] + vel[:-1]) * h, axis=0)
    da = lag.ea * a0 + lag.ca * u - acc[-1]
    dv = lag.ia * a0 + lag.cv * u - vel[-1]
    dp = lag.iia * a0 + lag.cp * u - pos
    return max(float(np.linalg.norm(da)), float(np.linalg.norm(dv)) / t,
               2.0 * float(np.linalg.norm(dp)) / (t * t))


@lru_cache(maxsize=8)
def _table(veh: VehicleConfig, uset: ProjectedInputSet, horizon: float, jump: float) -> tuple[
        float, ...]:
    """:func:`model_error_table` (cached: every follower of a process shares it)."""
    tau = np.array([veh.tau_rollpitch_s, veh.tau_rollpitch_s, veh.tau_thrust_s])
    lag = LagCoefficients.of(tau, horizon)
    out: list[float] = []
    worst = 0.0
    for b in A0_BINS:  # the bins are nested: each starts from the smaller one's worst
        axis = np.linspace(-b, b, GRID_POINTS)
        for a0 in itertools.product(axis, repeat=3):
            a = np.array(a0)
            if max(abs(x) for x in a0) < b - 1e-12 or not uset.contains(a):
                continue  # inside a smaller bin (done) or not realisable
            for d in JUMP_DIRS:
                u = a + jump * d
                if uset.contains(u):
                    worst = max(worst, lag_model_error(a, u, veh, lag))
        out.append(SAMPLING_FACTOR * worst)
    return tuple(out)


def model_error_table(
    veh: VehicleConfig, uset: ProjectedInputSet, horizon: float, jump: float,
) -> tuple[float, ...]:
    """ē_model (m/s²) per bin of :data:`A0_BINS`: :data:`SAMPLING_FACTOR` × the largest
    :func:`lag_model_error` over the realisable a0 of a grid of the cube ``‖a0‖∞ ≤ b``
    (:data:`GRID_POINTS` per axis; every smaller bin's grid too) and the realisable
    ``u = a0 + J d`` (d the box's corners, edge midpoints and face centres,
    :data:`JUMP_DIRS`), horizon T (s), J = ``jump`` (m/s²). Non-decreasing in b."""
    return _table(veh, uset, float(horizon), float(jump))


@dataclass
class TrustRegion:
    """One follower's trust region: the smallest bound J (m/s²), ē_base (m/s²), the full
    margin (m/s²) it falls back to, its vehicle's input set and horizon T (s).

    The bound of a step is the smallest of the levels ``J·2^i`` (i < :data:`LEVELS`) at or
    above ``ESCALATE·‖u_prev − a0‖∞``: while the box binds, the previous command sits on
    it, and the next step's bound is a level up (the box limits the jump of one step, not
    the rate of a manoeuvre); once the command settles, a0 catches up and the bound
    comes back down. The rows' margin is ``ē_base + ē_model(J, b(a0))``."""

    jump: float
    base_err: float
    full_err: float
    veh: VehicleConfig
    uset: ProjectedInputSet
    horizon: float

    def level(self, a0: np.ndarray, u_prev: np.ndarray) -> float:
        """The step's bound J (m/s²), 0 when even the largest level is below the wish."""
        want = ESCALATE * float(np.max(np.abs(u_prev - a0)))
        j = self.jump
        for _ in range(LEVELS):
            if want <= j:
                return j
            j *= 2.0
        return 0.0

    def margin(self, a0: np.ndarray, jump: float) -> float:
        """ē(J, a0) (m/s²) of the tight rows for realised acceleration ``a0`` and bound
        ``jump``, or 0 when the tight QP is not tried this step: a0 outside every bin, or
        a margin no smaller than the full one."""
        r = float(np.max(np.abs(a0)))
        if not math.isfinite(r) or jump <= 0.0:
            return 0.0
        for i, b in enumerate(A0_BINS):
            if r <= b:
                err = model_error_table(self.veh, self.uset, self.horizon, jump)[i]
                e = self.base_err + err
                return e if e < self.full_err else 0.0
        return 0.0
