"""The dashboard's pre-flight checks (gcs.dashboard.view.preflight), checked numerically."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ROOT

from gcs.dashboard.view.preflight import (
    CHECKED_PARAMS,
    desired_states,
    param_agreement,
    plan_envelope,
)
from swarm_common.scenario.model import load_scenario

CUBE8 = ROOT / "scenarios" / "cube8.toml"
COURSE8 = ROOT / "scenarios" / "course8.toml"


@pytest.mark.parametrize("path", [CUBE8, COURSE8], ids=["sinusoid", "mission"])
def test_velocities_are_the_derivative_of_the_places(path) -> None:
    sc = load_scenario(path)
    t = np.array([3.0, 11.7, 23.3])
    h = 1e-4
    p, v = desired_states(sc, t)
    pp, _ = desired_states(sc, t + h)
    pm, _ = desired_states(sc, t - h)
    fd = (pp - pm) / (2 * h)
    assert np.max(np.abs(fd - v)) < 1e-5 * max(1.0, float(np.max(np.abs(v))))
    assert p.shape == (3, len(sc.ids), 3)


def test_cube8_envelope_against_a_dense_brute_force() -> None:
    sc = load_scenario(CUBE8)
    env = plan_envelope(sc)
    # the sinusoid's leaders move; the cube keeps its shape (bearings): pairs never closer
    # than the cube's edge at the leaders' distance, and the envelope is sampled finely
    times = np.linspace(0.0, sc.run.duration_s, 4001)
    p, v = desired_states(sc, times)
    assert env.max_altitude_m == pytest.approx(p[..., 2].max(), abs=0.02)
    assert env.max_speed_m_s == pytest.approx(np.linalg.norm(v, axis=-1).max(), rel=0.01)
    d = np.linalg.norm(p[:, :, None] - p[:, None], axis=-1)
    d[:, np.arange(8), np.arange(8)] = np.inf
    assert env.min_pair_m == pytest.approx(d.min(), abs=0.01)
    assert env.pairs_apart and env.max_speed_m_s > 0.1 and env.max_altitude_m > 1.0
    assert "closest pair" in env.line()


def test_param_agreement_names_the_vehicle_that_differs() -> None:
    base = {n: 1.0 for n in CHECKED_PARAMS}
    same = {i: dict(base) for i in (1, 2, 3)}
    ok = param_agreement(same, [1, 2, 3])
    assert ok.agree and ok.line() == "params agree (3/3 vehicles)"
    diff = {**same, 2: {**base, "MPC_XY_VEL_MAX": 5.0}}
    bad = param_agreement(diff, [1, 2, 3])
    assert not bad.agree and set(bad.differing) == {"MPC_XY_VEL_MAX"}
    assert "#2=5" in bad.line() and "DIFFER" in bad.line()
    partial = param_agreement({1: base, 2: {"MPC_XY_VEL_MAX": 1.0}}, [1, 2, 3])
    assert not partial.agree and partial.heard == 1 and "1/3" in partial.line()
    # float rounding (PARAM_VALUE is float32) is no disagreement
    f32 = {**same, 3: {**base, "MPC_TKO_SPEED": float(np.float32(1.0))}}
    assert param_agreement(f32, [1, 2, 3]).agree
    assert math.isfinite(param_agreement({}, [1]).heard)
