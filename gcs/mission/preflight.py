"""What a run checks before it starts that needs the agents' own code (the scenario loader,
in ``swarm_common``, cannot import it): whether the formation can form at all under the
dcbf filter (docs/safety.md 5f, "Dense formations: liveness").

:func:`liveness_problem` is one line or None; :func:`warn_liveness` logs it as a WARNING.
It is a warning, not a refusal: such a run stays safe, it only never forms, and its
followers then raise the DEADLOCK event in flight.
"""

from __future__ import annotations

import logging

import numpy as np

from offboard.estimation.bearing import formation_from_scenario
from offboard.safety.dcbf.liveness import rest_spacing_m
from swarm_common.enums import Method
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)


def smallest_spacing_m(sc: Scenario) -> float:
    """The smallest distance (m) between two desired positions of ``sc``'s formation at its
    start, times the smallest scale its [mission] flies (1 without one)."""
    form = formation_from_scenario(sc)
    lead = sc.initial_positions()[[sc.index_of(i) for i in sc.leader_ids]]
    p = form.desired_positions(lead)
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    d[np.diag_indices(len(p))] = np.inf
    scale = 1.0
    if sc.mission is not None and sc.mission.waypoints:
        scale = min(1.0, min(w.scale for w in sc.mission.waypoints))
    return float(d.min()) * scale


def liveness_problem(sc: Scenario, method: str) -> str | None:
    """One line when ``method`` is dcbf and two desired positions are closer than the
    spacing d* at which the filter lets two agents hover (``rest_spacing_m``), else None."""
    if method != Method.DCBF:
        return None
    c, v = sc.controller, sc.vehicle
    d_star = rest_spacing_m(v.tau_rollpitch_s, v.tau_thrust_s, sc.control_dt, c.tau_safe_s,
                            c.d_safe_m, c.dcbf_gamma_lin, c.dcbf_gamma_cubic,
                            c.dcbf_accel_error_mps2)
    spacing = smallest_spacing_m(sc)
    if spacing >= d_star:
        return None
    return (f"{sc.name}: two desired positions are {spacing:.2f} m apart, closer than the "
            f"{d_star:.2f} m at which dcbf lets two agents hover (controller."
            f"dcbf_accel_error_mps2 = {c.dcbf_accel_error_mps2:g}, dcbf_gamma_lin = "
            f"{c.dcbf_gamma_lin:g}): the formation cannot form (docs/safety.md 5f)")


def warn_liveness(sc: Scenario, method: str) -> bool:
    """Log :func:`liveness_problem` as a WARNING; True when there was one."""
    line = liveness_problem(sc, method)
    if line is not None:
        log.warning("%s", line)
    return line is not None
