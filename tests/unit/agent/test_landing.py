"""Landing plan and reference (offboard.agent.landing, docs/lifecycle.md)."""

from pathlib import Path

import numpy as np
import pytest
from conftest import load_shipped

from offboard.agent.landing import (
    V_D,
    LandingReference,
    landing_plan,
    planned_positions,
)
from offboard.agent.takeoff import ramped_travel
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.toml"))


@pytest.mark.full
@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_pads_separated_and_off_descent_paths(path: Path) -> None:
    sc = load_shipped(path)
    plan = landing_plan(sc, 15.0)
    two_d = 2.0 * sc.controller.d_safe_m
    n = sc.n
    p0 = planned_positions(sc, 15.0)
    for i in range(n):
        for j in range(i + 1, n):
            assert np.linalg.norm(plan.pads[i] - plan.pads[j]) >= two_d
    # each agent's descent starts where its reference is at descent_delay after t_L; the
    # horizontal segment from there to its pad must stay 2 D_safe from every other pad
    for i in range(n):
        ref = LandingReference(plan, i, np.r_[p0[i], np.zeros(9)])
        start = ref.xi(15.0 + plan.descent_delay[i])[:2]
        for s in np.linspace(0.0, 1.0, 21):
            q = start + s * (plan.pads[i] - start)
            for j in range(n):
                if j != i and plan.descent_delay[j] >= plan.descent_delay[i]:
                    # a pad whose owner descends no earlier than i must not be under i's path
                    assert np.linalg.norm(q - plan.pads[j]) >= two_d - 1e-9


def test_cube8_stacks_get_distinct_pads_lowest_first() -> None:
    sc = load_scenario(ROOT / "scenarios" / "cube8.toml")
    plan = landing_plan(sc, 15.0)
    p0 = planned_positions(sc, 15.0)
    low = p0[:, 2] < 4.0
    # bottom layer keeps its footprint and descends first; the top layer moves outward
    assert np.allclose(plan.pads[low], p0[low, :2], atol=1e-9)
    assert np.all(plan.descent_delay[low] == 0.0)
    assert np.all(plan.descent_delay[~low] > 0.0)
    assert np.all(np.linalg.norm(plan.pads[~low] - p0[~low, :2], axis=1) > 1.0)


def test_plan_is_deterministic() -> None:
    sc = load_scenario(ROOT / "scenarios" / "cube8.toml")
    a, b = landing_plan(sc, 12.3), landing_plan(sc, 12.3)
    assert np.array_equal(a.pads, b.pads)
    assert np.array_equal(a.descent_delay, b.descent_delay)
    assert a.t_h == b.t_h


def test_reference_smooth_bounded_and_ends_on_pad() -> None:
    sc = load_scenario(ROOT / "scenarios" / "cube8.toml")
    plan = landing_plan(sc, 15.0)
    xi0 = np.r_[[0.1, 0.2, 6.0], [0.3, -0.2, 0.1], [0.5, 0.0, -0.2], np.zeros(3)]
    ref = LandingReference(plan, 2, xi0)
    assert np.allclose(ref.xi(15.0)[:9], xi0[:9])
    ts = np.arange(15.0, ref.t_end + 2.0, 0.01)
    xs = np.array([ref.xi(t) for t in ts])
    assert np.all(xs[:, 5] >= -V_D - 0.05)  # bounded descent speed (after the initial blend)
    # continuity of p, v, a (finite differences small between samples)
    assert np.max(np.abs(np.diff(xs[:, :9], axis=0))) < 0.1
    # p' = v numerically
    assert np.allclose(np.diff(xs[:, :3], axis=0) / 0.01, xs[:-1, 3:6], atol=0.02)
    assert np.allclose(xs[-1, :2], plan.pads[2]) and xs[-1, 2] == pytest.approx(0.0, abs=1e-9)
    assert ref.ended(ts[-1]) and not ref.ended(16.0)


def test_descent_profile_distance_and_speed() -> None:
    dz = 4.0
    t_end = dz / V_D + 1.0
    assert ramped_travel(t_end + 1.0, dz, V_D)[0] == pytest.approx(dz)
    assert ramped_travel(0.5 * t_end, dz, V_D)[1] == pytest.approx(V_D)
    ss = np.linspace(0.0, t_end, 2001)
    d = np.array([ramped_travel(s, dz, V_D)[0] for s in ss])
    assert np.all(np.diff(d) >= -1e-12)
