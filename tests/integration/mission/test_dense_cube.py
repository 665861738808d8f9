"""A dense cube (edge 2 m, D_safe 0.5 m) forms in process with dcbf, the true barrier of
every pair staying ≥ 0 (docs/safety.md, "Dense formations: liveness"); with cube8's
filter margins the same cube never forms, because its spacing is inside the filter's rest
spacing (offboard.safety.dcbf.liveness)."""

import numpy as np
import pytest
from conftest import ROOT  # noqa: E402

from gcs.mission.inproc import run_inproc
from gcs.report.verdict import pair_barrier
from offboard.safety.dcbf.liveness import rest_spacing_m
from swarm_common.scenario.model import load_scenario, with_overrides

DENSE2 = ROOT / "scenarios" / "dense_cube2.toml"


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(DENSE2)


def _rest_spacing(sc, **ctl) -> float:
    c, v = sc.controller, sc.vehicle
    kw = dict(tau_s=c.tau_safe_s, d_safe=c.d_safe_m, gamma1=c.dcbf_gamma_lin,
              gamma3=c.dcbf_gamma_cubic, accel_err=c.dcbf_accel_error_mps2) | ctl
    return rest_spacing_m(v.tau_rollpitch_s, v.tau_thrust_s, sc.control_dt, **kw)


def test_the_shipped_margins_let_neighbours_hover_at_the_edge(scenario):
    """Edge 2 m: inside cube8's rest spacing (2.75 m), outside the scenario's."""
    assert _rest_spacing(scenario) < 2.0 - 0.1
    assert _rest_spacing(scenario, gamma1=0.3, accel_err=2.0) > 2.0


def test_dense_cube_forms_with_every_true_barrier_nonnegative(scenario):
    r = run_inproc(scenario, "dcbf", seed=1, duration=16.0)
    m, s = r.metrics, r.series
    assert m["formation_time_s"] is not None and m["formation_time_s"] < 14.0
    h = pair_barrier(s.p, s.v, scenario.controller.tau_safe_s, scenario.controller.d_safe_m)
    assert np.min(h) >= 0.0
    assert m["collisions"] == 0 and m["min_distance_m"] >= scenario.controller.d_safe_m


def test_a_cube_that_cannot_form_reports_a_deadlock_and_stays_safe():
    """dense_cube1p5 with cube8's filter (margins and sidestep; its spacing inside d*), not
    its own trust region: the followers' formation errors
    stall with the filter holding them; those that also stay put for a detector window
    (6 s, less than 0.5 m of travel) raise the DEADLOCK liveness event, the first a window
    after the start (measured: agent 5 at 7.1 s, four more by 16 s; the others creep and
    are not named). The verdict stays "safe" (a liveness event is not a safety break),
    while cube8 forms and raises none."""
    sc = with_overrides(load_scenario(ROOT / "scenarios" / "dense_cube1p5.toml"), controller={
        "dcbf_trust_jump_mps2": 0.0, "dcbf_trust_error_mps2": 0.0, "dcbf_accel_error_mps2": 2.0,
        "dcbf_gamma_lin": 0.3, "deadlock_h_m2": 3.0})
    m = run_inproc(sc, "dcbf", seed=1, duration=12.0).metrics
    stalled = {e["agent"] for e in m["safety_alarms"] if e["assumption"] == "deadlock"}
    assert stalled and stalled <= set(sc.follower_ids)
    assert m["safety_verdict"] == "safe" and m["formation_time_s"] is None
    cube8 = run_inproc(load_scenario(ROOT / "scenarios" / "cube8.toml"), "dcbf", seed=1,
                       duration=10.0).metrics
    assert cube8["safety_alarm_count"] == 0


def test_a_dense_cube_at_a_short_range_brakes_for_the_pairs_it_hears(scenario):
    """dense_cube2 with a 3 m range (below its 3.46 m span) and the transient speed limit
    that its refusal names (0.3 m/s; docs/safety.md §5j). The speed rows give way to the
    pair rows in its crowded first seconds, and two followers that hear each other came
    into range closing at 2.2 m/s: the true barrier (pairs 4–8, then 4–7) went below 0
    from t = 2.76 s, to −1.99 m², when rows began at the range. With rows for heard
    neighbours beyond the range, those pairs brake before it and every true barrier
    stays ≥ 0."""
    sc = with_overrides(scenario, formation={"sensing_range_m": 3.0},
                        controller={"max_transient_speed_mps": 0.3})
    r = run_inproc(sc, "dcbf", seed=1, duration=5.0)
    h = pair_barrier(r.series.p, r.series.v, sc.controller.tau_safe_s, sc.controller.d_safe_m)
    assert np.min(h) >= 0.0
    assert r.metrics["collisions"] == 0
