"""A recorded run as the in-process runner's Series (gcs.mission.score.recorder_series):
the truth's derived rows for the recorded steps, and a recording with no truth yet (an
aborted start) giving an empty Series rather than an error."""

from __future__ import annotations

import numpy as np
from conftest import CUBE8

from gcs.mission.recorder import Recorder
from gcs.mission.run_output import tilt_deg
from gcs.mission.score import recorder_series
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario


def test_a_recording_without_truth_gives_an_empty_series() -> None:
    sc = load_scenario(CUBE8)
    ser = recorder_series(Recorder(sc, 10), sc)
    assert ser.p.shape == ser.p_des.shape == (0, sc.n, 3) and ser.tilt_deg.shape == (0, sc.n)


def test_recorded_truth_rows_give_the_desired_states_and_tilt_of_each_step() -> None:
    sc = load_scenario(CUBE8)
    form = formation_from_scenario(sc)
    rec = Recorder(sc, 10)
    rng = np.random.default_rng(2)
    steps = [0, 1, 2, 4, 5]  # step 3 never arrived
    for k in range(7):
        rec.min_dist[k] = 1.0
    for k in steps:
        rec.p[k], rec.v[k] = rng.normal(0.0, 4.0, (2, sc.n, 3)).astype(np.float32)
        rec.att[k] = rng.uniform(-0.4, 0.4, (sc.n, 3)).astype(np.float32)
        rec.have_truth[k] = True
    ser = recorder_series(rec, sc)
    assert len(ser.p) == len(steps)
    for r, k in enumerate(steps):
        p, v = rec.p[k].astype(float), rec.v[k].astype(float)
        assert np.allclose(ser.p_des[r], form.desired_positions(p[form.leader_idx]),
                           rtol=1e-13, atol=1e-12)
        assert np.allclose(ser.v_des[r], form.desired_positions(v[form.leader_idx]),
                           rtol=1e-13, atol=1e-12)
        assert np.array_equal(ser.tilt_deg[r], tilt_deg(rec.att[k].astype(float)))


def test_late_steps_reads_the_simulators_lockstep_timeouts() -> None:
    from gcs.mission.score import late_steps

    assert late_steps({}) == 0 and late_steps({"run": {"simulator": None}}) == 0
    assert late_steps({"run": {"simulator": {"lockstep_timeouts": 339}}}) == 339
