"""Reference governor: slow an infeasible leader trajectory until it fits the input set
(docs/saturation.md §3).

Every leader flies ``p_L(t) = p_L(0) + A(1 − cos ωt)`` and every agent's desired motion is
the same translation (swarm_common.scenario.feasibility), with needed command per axis
``u_ff(t) = Aω² cos ωt − τAω³ sin ωt`` plus the bound ``e(p*, v*)`` on what the controller
must cancel (disturbance, unmodeled dynamics at the desired velocity ``Aω sin ωt``). Every
term grows with ω, so the load-time check
:func:`swarm_common.scenario.feasibility.acceleration_problem`
is monotone in the frequency: there is a largest governed frequency ``ω_g = κω``
(0 < κ ≤ 1) at which the need stays inside the input set kept after the feedback reserve.

κ is found by bisection on that check (the first guess ``sqrt(a_avail / a_need)`` is what
κ would be if the need were a pure ``Aω²``; the lag and drag terms make the exact κ a little
smaller). It depends on the scenario alone, so every agent, in process or in its own daemon,
computes the same ω_g: the leaders fly the slowed trajectory and the followers' exosystem
``x'''' = −ω_g² x''`` (offboard.estimation.reference) generates exactly what the leaders fly. κ = 1
for
every scenario that passes the load-time check; κ < 1 only for one loaded with
``allow_infeasible``. When slowing cannot help (the disturbance and unmodeled bounds alone
exceed the set) κ stays 1 and the anti-windup of the nominal controller
(:func:`offboard.safety.rcbf.clf_rcbf.clf_terms_of_reference`) keeps the error bounded.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from swarm_common.memo import IdentityMemo
from swarm_common.scenario.feasibility import (
    FEEDBACK_RESERVE,
    acceleration_problem,
    desired_origins,
    leader_origins,
    peak_acceleration,
)
from swarm_common.scenario.input_set import InputSet
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

BISECT_STEPS = 40  # κ to 1e-12 of its bracket


@dataclass(frozen=True)
class Governor:
    """The governed trajectory of a scenario: κ = ω_g/ω and the frequency ``f_g`` (Hz)."""

    kappa: float
    frequency_hz: float  # f_g = κ f (Hz)
    nominal_hz: float  # the scenario's f (Hz)

    @property
    def omega(self) -> float:
        """ω_g = 2π f_g (rad/s)."""
        return 2.0 * math.pi * self.frequency_hz

    @property
    def slowed(self) -> bool:
        """True when the trajectory is slowed (κ < 1)."""
        return self.kappa < 1.0


def _at_frequency(sc: Scenario, f_hz: float) -> Scenario:
    """``sc`` with the leader trajectory's frequency replaced (no re-validation: the
    frequency is only ever lowered from a validated one)."""
    return replace(sc, leader_trajectory=replace(sc.leader_trajectory, frequency_hz=f_hz))


def _origins(sc: Scenario) -> tuple[np.ndarray, list[int]]:
    """Desired origins and the checked agent indices (as swarm_common.scenario.feasibility)."""
    origins = desired_origins(sc)
    if origins is not None:
        return origins, list(range(sc.n))
    idx = [sc.index_of(i) for i in sc.leader_ids]
    origins = np.zeros((sc.n, 3))
    origins[idx] = leader_origins(sc)
    return origins, idx


def first_guess(sc: Scenario) -> float:
    """``sqrt(a_avail / a_need)`` clipped to (0, 1]: a_need the peak horizontal ‖Aω²‖ plus
    the disturbance bound, a_avail the horizontal allowance at hover after the reserve
    (m/s²); exact if the need were the acceleration alone."""
    acc, _ = peak_acceleration(sc)
    d = sc.disturbance.amplitude_n / sc.vehicle.mass_kg
    need = float(np.linalg.norm(acc[:2])) + d
    limits = InputSet.of(sc.vehicle, sc.controller)
    avail = float(limits.horizontal(np.asarray(0.0), FEEDBACK_RESERVE))
    if need <= 0.0 or avail <= 0.0:
        return 1.0
    return min(1.0, math.sqrt(avail / need))


def governor_for(sc: Scenario) -> Governor:
    """The governed frequency of ``sc`` (module docstring): κ = 1 when the trajectory fits,
    else the largest κ < 1 (bisection) at which it does. Computed once per scenario object
    and process (its cost is a dense formation map per check: 30 ms at 64 agents)."""
    return _governors.get(sc, (), lambda: _governor(sc))


def _governor(sc: Scenario) -> Governor:
    f = sc.leader_trajectory.frequency_hz
    if f <= 0.0:
        return Governor(1.0, f, f)
    origins, idx = _origins(sc)

    def fits(kappa: float) -> bool:
        return acceleration_problem(_at_frequency(sc, kappa * f), origins, idx) is None

    if fits(1.0):
        return Governor(1.0, f, f)
    if not fits(1e-6):  # not the trajectory: slowing does not help
        return Governor(1.0, f, f)
    lo, hi = 1e-6, 1.0
    guess = first_guess(sc)
    if guess < 1.0:
        if fits(guess):
            lo = guess
        else:
            hi = guess
    for _ in range(BISECT_STEPS):
        mid = 0.5 * (lo + hi)
        if fits(mid):
            lo = mid
        else:
            hi = mid
    return Governor(lo, lo * f, f)


# every agent of a scenario in one process gets its governor computed once
_governors: IdentityMemo[Governor] = IdentityMemo()


def log_governor(gov: Governor, agent_id: int) -> None:
    """One start-up line when the trajectory is slowed."""
    if gov.slowed:
        log.warning(
            "agent %d: leader trajectory slowed to %.4g Hz (kappa = %.3f of %.4g Hz) so the "
            "desired motion fits the input set (docs/saturation.md)",
            agent_id, gov.frequency_hz, gov.kappa, gov.nominal_hz,
        )
