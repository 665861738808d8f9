"""What the operator checks before take-off: the plan's envelope and the vehicles' parameters.

* :func:`plan_envelope` - over the whole run (``[run] duration_s``), sampled every
  :data:`SAMPLE_S`, the desired formation that the leaders' plan fixes (the scenario's
  ``[mission]``, else the paper's leader sinusoid with the followers' bearing-defined
  places): the highest altitude, the smallest distance between two agents' places and the
  fastest agent's speed, beside the safety distance. Pure numpy over the same objects the
  agents fly (:class:`~swarm_common.mission.timeline.MissionTimeline`,
  :class:`~offboard.estimation.reference.LeaderTrajectory`,
  :class:`~offboard.estimation.bearing.Formation`).
* :func:`param_agreement` - the parameters that shape a flight (:data:`CHECKED_PARAMS`), as
  each vehicle reported them (PARAM_VALUE): whether all vehicles agree, and which
  parameter differs on which vehicle.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from offboard.agent.governor import governor_for
from offboard.agent.takeoff import leader_origin
from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.reference import LeaderTrajectory
from swarm_common.scenario.mission_check import timeline_for
from swarm_common.scenario.model import Scenario

SAMPLE_S = 0.05  # s between two samples of the plan
PAIR_CHUNK = 64  # samples whose pair distances are computed at once
# PX4 parameters whose disagreement between vehicles changes how the swarm flies
CHECKED_PARAMS = (
    "MPC_XY_VEL_MAX", "MPC_Z_VEL_MAX_UP", "MPC_Z_VEL_MAX_DN", "MPC_TKO_SPEED",
    "MPC_LAND_SPEED", "MIS_TAKEOFF_ALT", "COM_OF_LOSS_T", "COM_OBL_RC_ACT", "GF_ACTION",
)  # fmt: skip
PARAM_RTOL = 1e-6  # two float parameters agree within this relative difference


@dataclass(frozen=True)
class PlanEnvelope:
    """The desired formation's extremes over the run (ENU, m and m/s)."""

    max_altitude_m: float
    min_pair_m: float
    max_speed_m_s: float
    d_safe_m: float
    duration_s: float

    @property
    def pairs_apart(self) -> bool:
        """Every two agents' places stay farther apart than the safety distance."""
        return self.min_pair_m > self.d_safe_m

    def line(self) -> str:
        return (f"plan over {self.duration_s:g} s: altitude <= {self.max_altitude_m:.1f} m, "
                f"closest pair {self.min_pair_m:.2f} m (D_safe {self.d_safe_m:g} m), "
                f"speed <= {self.max_speed_m_s:.1f} m/s")


def desired_states(sc: Scenario, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, N, 3) desired positions (m) and velocities (m/s) of every agent at ``times`` (s)."""
    n = len(sc.ids)
    p = np.empty((len(times), n, 3))
    v = np.empty_like(p)
    if sc.mission is not None:
        tl = timeline_for(sc)
        for k, t in enumerate(times):
            xi = tl.all_xi(float(t))
            p[k], v[k] = xi[:, 0:3], xi[:, 3:6]
        return p, v
    form = formation_from_scenario(sc)
    lt = sc.leader_trajectory
    hz = governor_for(sc).frequency_hz
    trajs = [LeaderTrajectory(leader_origin(sc, i), np.array(lt.amplitude_m), hz)
             for i in form.leader_idx]
    for k, t in enumerate(times):
        xi = np.array([tr.state(float(t)) for tr in trajs])
        # the bearing formation's places are linear in the leaders' positions: so are
        # their velocities in the leaders' velocities
        p[k] = form.desired_positions(xi[:, 0:3])
        v[k] = form.desired_positions(xi[:, 3:6])
    return p, v


def plan_envelope(sc: Scenario, sample_s: float = SAMPLE_S) -> PlanEnvelope:
    """The plan's envelope over ``[0, duration_s]`` sampled every ``sample_s`` (s)."""
    duration = float(sc.run.duration_s)
    times = np.linspace(0.0, duration, max(2, int(math.ceil(duration / sample_s)) + 1))
    p, v = desired_states(sc, times)
    iu = np.triu_indices(p.shape[1], 1)
    min_pair = math.inf
    for k in range(0, len(times), PAIR_CHUNK):  # (chunk, N, N) at a time: bounded memory
        q = p[k:k + PAIR_CHUNK]
        d = np.linalg.norm(q[:, :, None, :] - q[:, None, :, :], axis=-1)[:, iu[0], iu[1]]
        if d.size:
            min_pair = min(min_pair, float(d.min()))
    return PlanEnvelope(
        max_altitude_m=float(p[..., 2].max()),
        min_pair_m=min_pair,
        max_speed_m_s=float(np.linalg.norm(v, axis=-1).max()),
        d_safe_m=float(sc.controller.d_safe_m),
        duration_s=duration,
    )


@dataclass(frozen=True)
class ParamAgreement:
    """How the vehicles' :data:`CHECKED_PARAMS` compare."""

    heard: int  # vehicles that reported every checked parameter
    expected: int
    differing: dict[str, dict[int, float]]  # parameter -> {vehicle id: its value}

    @property
    def agree(self) -> bool:
        return self.heard == self.expected and not self.differing

    def line(self) -> str:
        if self.differing:
            name, vals = next(iter(self.differing.items()))
            who = ", ".join(f"#{i}={x:g}" for i, x in sorted(vals.items()))
            more = f" (+{len(self.differing) - 1} more)" if len(self.differing) > 1 else ""
            return f"params DIFFER: {name} {who}{more}"
        if self.heard < self.expected:
            return f"params: {self.heard}/{self.expected} vehicles reported"
        return f"params agree ({self.heard}/{self.expected} vehicles)"


def param_agreement(values: Mapping[int, Mapping[str, float]], ids: list[int],
                    names: tuple[str, ...] = CHECKED_PARAMS) -> ParamAgreement:
    """Compare ``values`` (vehicle id -> {parameter: value}) over ``names``: a parameter
    differs when two vehicles that reported it disagree (relative :data:`PARAM_RTOL`)."""
    heard = sum(1 for i in ids if all(n in values.get(i, {}) for n in names))
    differing: dict[str, dict[int, float]] = {}
    for n in names:
        got = {i: float(values[i][n]) for i in ids if n in values.get(i, {})}
        if len(got) < 2:
            continue
        ref = next(iter(got.values()))
        if any(not math.isclose(x, ref, rel_tol=PARAM_RTOL, abs_tol=1e-9) for x in got.values()):
            differing[n] = got
    return ParamAgreement(heard=heard, expected=len(ids), differing=differing)
