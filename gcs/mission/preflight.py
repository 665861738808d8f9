"""What a run checks before it starts, with what the scenario loader (in ``swarm_common``)
cannot use: the agents' own code and the machine's ports.

* :func:`liveness_problem` - whether the formation can form at all under the dcbf filter
  (docs/safety.md 5f, "Dense formations: liveness"): one line or None;
  :func:`observer_problem` - whether the desired-state observer is too slow for the
  formation to form (a large formation with few leaders; docs/scenarios.md);
  :func:`warn_liveness` logs them as WARNINGs, and a run's ``metrics.json`` lists them
  (``preflight``). It is a warning, not a refusal: such a run
  stays safe, it only never forms, and its followers then raise the DEADLOCK event in
  flight.
* :func:`check_physics` - the followers' DESO gains on the scenario's graph (a refusal)
  and a ``--duration`` that ends before the formation deadline (a warning).
* :func:`resolve_port_offset` - the port offset of a launch, forced or chosen, every one
  of its ports free (:mod:`gcs.mission.ports`).

A refusal is a :class:`~gcs.mission.launch_spec.LaunchError` (one line, exit 2).
"""

from __future__ import annotations

import logging

import numpy as np

from gcs.mission.launch_spec import MAX_PORT_OFFSET, LaunchError
from gcs.mission.ports import busy_uses, choose_port_offset, port_in_use_line, swarm_port_uses
from offboard.estimation.bearing import Formation, formation_from_scenario
from offboard.estimation.deso_gains import scenario_gain_problem
from offboard.safety.dcbf.filter import input_set_of
from offboard.safety.dcbf.liveness import rest_spacing_m
from offboard.safety.dcbf.trust import model_error_table
from swarm_common.enums import Method
from swarm_common.scenario.feasibility import deadline_problem
from swarm_common.scenario.files import run_anyway_hint
from swarm_common.scenario.model import ALLOW_INFEASIBLE_FLAG, Scenario

log = logging.getLogger(__name__)
# 1/s: the slowest desired-state observer channel below which a run is warned that it may
# not form. Measured on generated grids (docs/scenarios.md): 256 agents with 4 leaders
# (0.19 1/s) did not form in 60 s, 125 with 4 (0.41) formed at 29 s, 256 with 16 (1.36)
# at 7.9 s; every shipped scenario is at 0.76 1/s or more.
OBSERVER_RATE_MIN = 0.5


def smallest_spacing_m(sc: Scenario, form: Formation | None = None) -> float:
    """The smallest distance (m) between two desired positions of ``sc``'s formation at its
    start, times the smallest scale its [mission] flies (1 without one). ``form``: the
    scenario's formation when the caller has it built."""
    form = formation_from_scenario(sc) if form is None else form
    lead = sc.initial_positions()[[sc.index_of(i) for i in sc.leader_ids]]
    p = form.desired_positions(lead)
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    d[np.diag_indices(len(p))] = np.inf
    scale = 1.0
    if sc.mission is not None and sc.mission.waypoints:
        scale = min(1.0, min(w.scale for w in sc.mission.waypoints))
    return float(d.min()) * scale


def liveness_problem(sc: Scenario, method: str, form: Formation | None = None) -> str | None:
    """One line when ``method`` is dcbf and two desired positions are closer than the
    spacing d* at which the filter lets two agents hover (``rest_spacing_m``), else None.
    ``form``: the scenario's formation when the caller has it built."""
    if method != Method.DCBF:
        return None
    c, v = sc.controller, sc.vehicle
    key, e_bar = "dcbf_accel_error_mps2", c.dcbf_accel_error_mps2
    if c.dcbf_trust_jump_mps2 > 0.0:  # hovering, the trust region's margin at its least
        key, e_bar = "dcbf_trust_error_mps2", hover_margin(sc)
    d_star = rest_spacing_m(v.tau_rollpitch_s, v.tau_thrust_s, sc.control_dt, c.tau_safe_s,
                            c.d_safe_m, c.dcbf_gamma_lin, c.dcbf_gamma_cubic, e_bar,
                            vertical_scale=c.dcbf_vertical_scale)
    spacing = smallest_spacing_m(sc, form)
    if spacing >= d_star:
        return None
    scale = (f", dcbf_vertical_scale = {c.dcbf_vertical_scale:g}"
             if c.dcbf_vertical_scale != 1.0 else "")
    return (f"{sc.name}: two desired positions are {spacing:.2f} m apart, closer than the "
            f"{d_star:.2f} m at which dcbf lets two agents hover (controller."
            f"{key} = {getattr(c, key):g}, dcbf_gamma_lin = "
            f"{c.dcbf_gamma_lin:g}{scale}): the formation cannot form (docs/safety.md 5f)")


def hover_margin(sc: Scenario) -> float:
    """The dcbf trust region's margin ē (m/s²) for a hovering agent (a0 = u = 0): its
    ē_base plus the lag model's error for its smallest bound in the smallest bin
    (:mod:`offboard.safety.dcbf.trust`)."""
    c, v = sc.controller, sc.vehicle
    table = model_error_table(v, input_set_of(c, v), v.tau_rollpitch_s + sc.control_dt,
                              c.dcbf_trust_jump_mps2)
    return c.dcbf_trust_error_mps2 + table[0]


def observer_problem(sc: Scenario, form: Formation | None = None) -> str | None:
    """One line when the desired-state observer's slowest channel, reference_gain ·
    λ_min(L_ff) (:attr:`offboard.estimation.reference.DesiredStateObserver.rate`), decays
    slower than :data:`OBSERVER_RATE_MIN`, else None (docs/scenarios.md, "Leaders for a
    large formation"). ``form``: the scenario's formation when the caller has it built."""
    form = formation_from_scenario(sc) if form is None else form
    gain = sc.observer.reference_gain
    rate = gain * form.lambda_min
    if rate >= OBSERVER_RATE_MIN:
        return None
    return (f"{sc.name}: the desired-state observer's slowest channel decays at {rate:.2f} "
            f"1/s (observer.reference_gain = {gain:g} x lambda_min = {form.lambda_min:.3f} "
            f"of the follower graph), below {OBSERVER_RATE_MIN:g} 1/s: its start-up errors "
            f"last tens of seconds and the formation may not form; more leaders (gcs "
            f"scenario --leaders) or a denser graph raise it (docs/scenarios.md)")


def warn_liveness(sc: Scenario, method: str, form: Formation | None = None) -> list[str]:
    """Log :func:`liveness_problem` and :func:`observer_problem` as WARNINGs and return
    their lines (a run keeps them in its document, ``preflight``). ``form``: the run's
    formation when the caller has it built. The checks compute its leader map (a cached
    solve), so the in-process runner calls this inside its ``single_thread_blas()`` block:
    that map's bits are the run's, and they depend on the BLAS threads."""
    form = formation_from_scenario(sc) if form is None else form
    lines = [line for line in (liveness_problem(sc, method, form), observer_problem(sc, form))
             if line is not None]
    for line in lines:
        log.warning("%s", line)
    return lines


def check_physics(sc: Scenario, duration: float) -> None:
    """What the loader cannot check (issue 42): the followers' DESO gains on this graph
    (:func:`~offboard.estimation.deso_gains.scenario_gain_problem`): a
    :class:`LaunchError` (exit 2), or a warning when the scenario
    was loaded with --allow-infeasible; and a ``--duration`` that ends the run before
    ``scenario.formation_deadline_s`` (a warning: a short smoke run is legitimate, but
    its tracking metrics are empty)."""
    late = deadline_problem(sc.run.formation_deadline_s, duration, "--duration")
    if late is not None:
        log.warning("%s: %s", sc.path, late)
    problem = scenario_gain_problem(sc)
    if problem is None:
        return
    if not sc.allow_infeasible:
        raise LaunchError(f"{sc.path}: {problem}{run_anyway_hint(ALLOW_INFEASIBLE_FLAG)}")
    log.warning("%s: %s (%s: running it anyway)", sc.path, problem, ALLOW_INFEASIBLE_FLAG)


def resolve_port_offset(
    sc: Scenario, forced: int | None, formation_base: int | None = None,
    gcs_port: bool = False,
) -> int:
    """The port offset of a launch of ``sc``: ``forced`` (``--port-offset N``) when every
    port it gives is free, else :class:`LaunchError` naming the first busy one; with
    ``forced`` None the first offset 0, 1000, ... whose ports are all free
    (:func:`gcs.mission.ports.choose_port_offset`, logged). Every port is bound and released
    here, before anything starts. ``formation_base``: the formation vehicle's UDP port at
    offset 0, when it is served; ``gcs_port``: also the GCS port (a ground station's)."""
    if forced is not None:
        fport = None if formation_base is None else formation_base + forced
        busy = busy_uses(swarm_port_uses(sc.ids, forced, True, gcs_port, fport))
        if busy:
            raise LaunchError(port_in_use_line(busy, can_choose=True))
        return forced
    off = choose_port_offset(sc.ids, MAX_PORT_OFFSET, True, gcs_port, formation_base)
    if off is None:
        raise LaunchError(f"no port offset 0..{MAX_PORT_OFFSET} has every port of "
                          f"{len(sc.ids)} agents free; pass one with --port-offset")
    return off
