"""The dashboard's mission progress (gcs.dashboard.view.mission_progress): the next waypoint, the
time to arrive, the fraction done and the planned centroid path, read from the replica of
the leaders' timeline; and the typed go-to's parser."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.dashboard.view.mission_progress import (
    MAX_PATH_POINTS,
    PATH_STEP_S,
    parse_goto,
    planned_path,
    progress_at,
)
from gcs.formation.steer import COMMAND_LEAD_S, FormationSteer
from swarm_common.mission.config import MissionError
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]
EPS = 1e-6  # s, just before / after an arrival


def course8() -> tuple[FormationSteer, list[np.ndarray]]:
    """course8's steer and the centroids of its [mission] waypoints (m), as the TOML says."""
    sc = load_scenario(ROOT / "scenarios" / "course8.toml")
    assert sc.mission is not None
    return FormationSteer(sc), [np.array(w.centroid, dtype=float) for w in sc.mission.waypoints]


def test_the_next_waypoint_advances_at_each_arrival():
    s, wps = course8()
    plan = s.timeline.plan_at(0.0)
    n = len(wps)
    for k, a in enumerate(plan.arrival_s):
        before, after = progress_at(s.timeline, a - EPS), progress_at(s.timeline, a + EPS)
        assert (before.next_index, before.reached, before.count) == (k, k, n)
        assert after.reached == k + 1
        assert after.next_index == min(k + 1, n - 1)
        np.testing.assert_allclose(before.next_centroid, wps[k], atol=1e-12)
        assert before.eta_s == pytest.approx(EPS, abs=1e-9)  # arriving now
        # where the formation is once there: the waypoint it was told (the plan's own maths)
        np.testing.assert_allclose(plan.centroid_at(a + EPS), wps[k], atol=1e-6)


def test_eta_falls_one_second_a_second_and_the_fraction_rises_in_0_1():
    s, _ = course8()
    plan = s.timeline.plan_at(0.0)
    ts = np.arange(-5.0, plan.end_s + 5.0, 0.05)
    ps = [progress_at(s.timeline, t) for t in ts]
    idx = np.array([p.next_index for p in ps])
    eta = np.array([p.eta_s for p in ps])
    frac = np.array([p.fraction for p in ps])
    assert np.all(np.diff(idx) >= 0) and idx[-1] == len(plan.legs) - 1
    same = (np.diff(idx) == 0) & (eta[1:] > 0) & (eta[:-1] > 0)
    assert same.sum() > 1000  # most samples are on the way to one waypoint
    np.testing.assert_allclose(np.diff(eta)[same], -0.05, atol=1e-9)  # dη/dt = -1
    assert np.all((frac >= 0.0) & (frac <= 1.0))
    assert np.all(np.diff(frac) >= -1e-15)
    assert frac[0] == 0.0 and frac[-1] == 1.0
    assert np.any((frac > 0.2) & (frac < 0.8))
    assert not ps[0].finished and ps[-1].finished and ps[-1].reached == len(plan.legs)
    assert "finished" in ps[-1].line() and "100 %" in ps[-1].line()


def test_the_path_runs_from_the_start_to_the_last_waypoint_at_no_more_than_max_speed():
    s, wps = course8()
    plan = s.timeline.plan_at(0.0)
    p = progress_at(s.timeline, 30.0)
    path = p.path
    assert path.ndim == 2 and path.shape[1] == 3 and 2 <= len(path) <= MAX_PATH_POINTS
    np.testing.assert_allclose(path[0], plan.legs[0].start.centroid, atol=1e-9)
    np.testing.assert_allclose(path[-1], wps[-1], atol=1e-9)
    # samples at most PATH_STEP_S apart: a centroid under the 3 m/s agent limit moves less
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert step.max() <= 3.0 * PATH_STEP_S + 1e-9
    # every waypoint is on the path (within 1e-9 m), in the mission's order
    at = 0
    for w in wps:
        on = np.flatnonzero(np.linalg.norm(path[at:] - w, axis=1) < 1e-9)
        assert len(on), f"waypoint {w} not on the path after sample {at}"
        at += int(on[0])
    assert planned_path(plan) is path  # cached per plan


def test_a_go_to_far_away_is_a_new_one_waypoint_plan_with_a_capped_path():
    s, _ = course8()
    target = np.array([600.0, 2.0, 4.0])
    cmd = s.goto(target, 4.0)
    assert cmd.kind == "mission"
    p = progress_at(s.timeline, 6.0)  # the new plan started at 5 s (4 s + the 1 s lead)
    assert (p.next_index, p.count, p.reached) == (0, 1, 0)
    np.testing.assert_allclose(p.next_centroid, target, atol=0)
    assert p.eta_s > (600.0 - 2.0) / 1.5 - 2.0  # at most cruise speed, from (2, 2, 4)
    assert len(p.path) == MAX_PATH_POINTS
    np.testing.assert_allclose(p.path[0], [2.0, 2.0, 4.0], atol=1e-9)
    np.testing.assert_allclose(p.path[-1], target, atol=1e-9)
    assert "waypoint 1/1 → (600.0, 2.0, 4.0)" in p.line()
    # before that plan starts, the old one is still in force
    assert progress_at(s.timeline, 4.5).count == 6


def test_a_hold_shows_holding_at_the_rest_pose():
    s, _ = course8()
    s.hold(30.0)  # course8 flies its second leg then: it stops at waypoint 3 (14, 2, 4)
    start, _ = s.timeline.plans[-1]
    p = progress_at(s.timeline, start + 5.0)
    assert p.holding and p.count == 0 and p.fraction == 1.0 and p.eta_s == 0.0
    np.testing.assert_allclose(p.next_centroid, s.timeline.plan_at(start).centroid_at(start))
    assert p.path.shape == (1, 3)
    assert p.line().startswith("holding at (") and "waypoint" not in p.line()
    assert not progress_at(s.timeline, start - 1.0).holding


@pytest.mark.parametrize(
    "text,centroid,yaw",
    [
        ("20 0 5", (20.0, 0.0, 5.0), None),
        ("20, 0, 5, 90", (20.0, 0.0, 5.0), 90.0),
        ("  -1.5,2e1 ,3  ", (-1.5, 20.0, 3.0), None),
        ("(1, 2, 3)", (1.0, 2.0, 3.0), None),
        ("[1 2 3 -45°]", (1.0, 2.0, 3.0), -45.0),
        ("1;2;3", (1.0, 2.0, 3.0), None),
    ],
)
def test_parse_goto_accepts(text, centroid, yaw):
    c, y = parse_goto(text)
    assert c.shape == (3,) and c.dtype == float
    np.testing.assert_array_equal(c, centroid)
    assert y == yaw


@pytest.mark.parametrize(
    "text,why",
    [
        ("", "got 0"), ("1 2", "got 2"), ("1,,2", "got 2"), ("1 2 3 4 5", "got 5"),
        ("1 x 3", "y = 'x': not a number"), ("nan 0 0", "x = 'nan': must be finite"),
        ("1 2 inf", "z = 'inf': must be finite"), ("1 2 3 -inf", "yaw = '-inf'"),
        ("1 2 3\n4 5", "got 5"), ("0x10 0 0", "not a number"),
    ],
)
def test_parse_goto_refuses_with_one_line(text, why):
    with pytest.raises(MissionError) as err:
        parse_goto(text)
    msg = str(err.value)
    assert why in msg and "\n" not in msg


def test_a_live_plan_shows_where_the_formation_will_stop() -> None:
    """Flown live (gcs.formation.live): the panel says where the formation stops unless
    steered on, and the path ends there; once at rest, it says so."""
    steer = FormationSteer(load_scenario(ROOT / "scenarios" / "course8.toml"))
    steer.live(np.array([1.0, 0.0, 0.0]), 2.0)
    at = 2.0 + COMMAND_LEAD_S
    plan = steer.timeline.plan_at(at)
    p = progress_at(steer.timeline, at + 0.5)
    assert p.live and not p.finished and "flown live" in p.line()
    stop = plan.centroid_at(plan.rest_s)
    np.testing.assert_allclose(p.next_centroid, stop, atol=1e-12)
    np.testing.assert_allclose(p.path[0], plan.centroid_at(at), atol=1e-12)
    np.testing.assert_allclose(p.path[-1], stop, atol=1e-12)
    assert stop[0] > plan.centroid_at(at)[0] + 1.0  # it flew east before stopping
    assert p.eta_s == pytest.approx(plan.rest_s - (at + 0.5), abs=1e-12)
    done = progress_at(steer.timeline, plan.rest_s + 1.0)
    assert done.finished and "at rest" in done.line()
