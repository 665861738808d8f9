"""The dcbf filter's world rows (offboard.safety.dcbf.world_rows, docs/world.md): the
rows against a numerical prediction of the lagged point mass; a scenario whose start or
leader path breaks a clearance is refused at load. The flight of cube8 with ten obstacles
is tests/integration/inproc/test_world_flight.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ROOT

from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.world_rows import plane_rows_into
from swarm_common.scenario.files import UnsafeScenarioError, dump_toml
from swarm_common.scenario.mission_check import plan_for
from swarm_common.scenario.model import load_scenario, parse_scenario

OBSTACLES = ROOT / "scenarios" / "cube8_obstacles.toml"
TAU, GAMMA, ERR = 0.8, 4.0, 1.0
LAGS = np.array([0.15, 0.15, 0.03])  # s: roll-pitch, roll-pitch, thrust


def _predict(p: np.ndarray, v: np.ndarray, a0: np.ndarray, w: np.ndarray, u: np.ndarray,
             horizon: float, dt: float = 1e-5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(p, v, a) after ``horizon`` s of ȧ = (u − a)/τ per axis, p̈ = a + w: Euler, fine."""
    p, v, a = p.copy(), v.copy(), a0.copy()
    for _ in range(round(horizon / dt)):
        p = p + v * dt
        v = v + (a + w) * dt
        a = a + (u - a) / LAGS * dt
    return p, v, a + w


@pytest.mark.full
def test_rows_are_the_barrier_conditions_of_the_predicted_state() -> None:
    # random planes, states and commands: g·u − r of each row equals its condition on the
    # state predicted by integrating the lagged point mass (scaled by 1/‖g‖; 1e-3 for the
    # Euler integration), with ē = 0
    rng = np.random.default_rng(3)
    t = 0.15 + 0.02
    lag = LagCoefficients.of(LAGS, t).table
    for _ in range(5):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        c = float(rng.normal())
        p, v, a0, w, u = (rng.normal(size=3) for _ in range(5))
        g, r = np.zeros((2, 3)), np.zeros(2)
        h0 = plane_rows_into(n[None], np.array([c]), 1, p, v, a0, w, lag, t, TAU, GAMMA,
                             0.0, 0.0, g, r, 0)
        assert h0 == pytest.approx(n @ p - c + TAU * n @ v, abs=1e-12)
        pt, vt, at = _predict(p, v, a0, w, u, t)
        h_t = n @ pt - c + TAU * n @ vt
        c1 = n @ vt + TAU * n @ at + GAMMA * h_t
        drop = min(t * GAMMA * h0, h0 / 2) if h0 > 0 else t * GAMMA * h0
        c2 = h_t - (h0 - drop)
        # each row is its condition divided by the norm of its u-coefficients: recover the
        # scale from a second command
        u2 = u + rng.normal(size=3)
        pt2, vt2, at2 = _predict(p, v, a0, w, u2, t)
        h_t2 = n @ pt2 - c + TAU * n @ vt2
        s1 = (n @ vt2 + TAU * n @ at2 + GAMMA * h_t2 - c1) / (g[0] @ (u2 - u))
        s2 = (h_t2 - h_t) / (g[1] @ (u2 - u))
        assert abs(s1 * (g[0] @ u - r[0]) - c1) < 1e-3
        assert abs(s2 * (g[1] @ u - r[1]) - c2) < 1e-3
        assert np.allclose(np.linalg.norm(g, axis=1), 1.0)


def _doc_with(extra: dict) -> dict:
    doc = load_scenario(OBSTACLES).to_toml_dict()
    doc.update(extra)
    return doc


def test_world_breaking_starts_and_leader_paths_are_refused() -> None:
    # agent 3 starts at (2, 0.4, 2.9): a sphere 0.3 m away from its centre
    start = _doc_with({"obstacle": [{"kind": "sphere", "centre_m": [2.0, 0.7, 2.9],
                                     "radius_m": 0.1}]})
    with pytest.raises(UnsafeScenarioError, match=r"obstacle\[0\] \(sphere\): agent 3 starts"):
        parse_scenario(start, "start.toml")
    # leader 1 flies x 4 → 5.6 m at y 0, z 6 → 6.4: a post at x = 5 on its way
    post = _doc_with({"obstacle": [{"kind": "cylinder", "centre_m": [5.0, 0.0],
                                    "radius_m": 0.1, "z_range_m": [0.0, 10.0]}]})
    with pytest.raises(UnsafeScenarioError, match="agent 1 flies its sinusoid"):
        parse_scenario(post, "post.toml")
    # agents 7 and 8 start at x = 6: 0.2 m inside a fence ending at 6.2 (margin 0.5)
    fence = _doc_with({"geofence": {"min_m": [-2.0, -2.0, 0.0], "max_m": [6.2, 7.0, 9.5]}})
    with pytest.raises(UnsafeScenarioError, match="geofence: agent"):
        parse_scenario(fence, "fence.toml")
    # --allow-unsafe: loaded, with the warning
    assert parse_scenario(post, "post.toml", allow_unsafe=True).world.obstacles


def test_world_round_trips_through_the_scenario_file() -> None:
    sc = load_scenario(OBSTACLES)
    import tomllib

    back = parse_scenario(tomllib.loads(dump_toml(sc.to_toml_dict())), "back.toml")
    assert back.world == sc.world and len(back.world.obstacles) == 10
    assert math.isclose(back.world.obstacles[0].clearance_m, sc.controller.d_safe_m)


def test_an_obstacle_on_a_leaders_mission_path_is_refused() -> None:
    # course8: a ball 0.6 m above where leader 1 passes mid-way along its second leg
    sc = load_scenario(ROOT / "scenarios" / "course8.toml")
    plan = plan_for(sc)
    k = next(i for i, a in enumerate(sc.agents) if a.is_leader)
    t = 0.5 * (plan.departure_s[0] + plan.arrival_s[1])
    q = plan.agent_xi(t, k)[0:3] + np.array([0.0, 0.0, 0.6])
    doc = sc.to_toml_dict()
    doc["obstacle"] = [{"kind": "sphere", "centre_m": [float(x) for x in q], "radius_m": 0.2}]
    with pytest.raises(UnsafeScenarioError, match=f"agent {sc.agents[k].id} flies its mission"):
        parse_scenario(doc, "course.toml")
    # 3 m above it: clear
    doc["obstacle"][0]["centre_m"][2] += 3.0
    assert parse_scenario(doc, "course.toml").world.obstacles
