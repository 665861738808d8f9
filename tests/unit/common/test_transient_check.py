"""Check (b) with the followers' transient speed limit (swarm_common.scenario.transient_check,
docs/safety.md §5i): the range's closing speed is the root of max(R_h, R_b) = R, a
simulated head-on entry at the bound keeps h ≥ 0 and stops before D, and the refusals
name the keys and the bound in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ROOT

from swarm_common.scenario import safety_check as chk
from swarm_common.scenario import transient_check as tc
from swarm_common.scenario.model import (
    Scenario,
    UnsafeScenarioError,
    load_scenario,
    parse_scenario,
)

CUBE8 = ROOT / "scenarios" / "cube8.toml"


def _cube8(range_m: float, v_t: float = 0.0, allow: bool = False) -> Scenario:
    data = load_scenario(CUBE8).to_toml_dict()
    data["formation"]["sensing_range_m"] = range_m
    data["controller"]["max_transient_speed_mps"] = v_t
    return parse_scenario(data, "variant.toml", allow_unsafe=allow)


def _refusal(range_m: float, v_t: float = 0.0) -> str:
    with pytest.raises(UnsafeScenarioError) as exc:
        _cube8(range_m, v_t)
    msg = str(exc.value)
    assert "\n" not in msg and "--allow-unsafe" in msg, msg
    return msg


def test_span_is_the_largest_distance_at_start_or_in_formation():
    sc = load_scenario(CUBE8)
    assert tc.span(sc) == pytest.approx(4.0 * math.sqrt(3.0), abs=0.01)  # the cube's diagonal
    assert not chk.pairs_enter(sc)  # range 10 m: every pair sensed from the start


@pytest.mark.parametrize("r", [5.7, 6.0, 6.9])
def test_range_speed_is_the_root_of_the_needed_range(r):
    sc = _cube8(r, allow=True)
    v = chk.range_speed(sc)
    assert chk.needed_range(sc, v) == pytest.approx(r, abs=1e-9)
    assert chk.needed_range(sc, 1.001 * v) > r


def test_closing_speed_bound_is_the_sum_of_the_transients():
    # follower-follower: v_ref + 2 u_f; a leader off its reference adds its own speed
    assert tc.limited_closing_speed(1.0, 1.2, 0.0, 0.0) == pytest.approx(3.2)
    assert tc.limited_closing_speed(1.0, 1.2, 2.5, 0.0) == pytest.approx(6.2)  # fast start
    assert tc.limited_closing_speed(1.0, 1.2, 0.0, 1.5) == pytest.approx(3.7)
    x = tc.largest_transient_speed(3.0, 1.2, 0.0)
    assert tc.limited_closing_speed(x, 1.2, 0.0, 0.0) == pytest.approx(3.0)


def test_head_on_entry_at_the_bound_is_safe():
    """Two followers each at v_t against the other (plus the reference's lag) come into
    range at R: h ≥ 0 there, and one braking at a_b after a period through the lag (the
    other flying on) stops before D."""
    sc = _cube8(5.7, 1.15)
    r, d = sc.formation.sensing_range_m, sc.controller.d_safe_m
    v_bar = chk.closing_speed(sc)
    assert v_bar == pytest.approx(tc.limited_closing_speed(
        1.15, chk.trajectory_speed(sc), *tc.start_speeds(sc)))
    h = chk.pair_barriers(np.array([[0.0, 0, 0], [r, 0, 0]]),
                          np.array([[v_bar, 0, 0], [0.0, 0, 0]]), sc.controller.tau_safe_s, d)
    assert h[0, 1] >= 0.0
    a_b, tau, dt = chk.braking_accel(sc), sc.vehicle.tau_rollpitch_s, sc.control_dt
    step, x, v, a, t = 1e-5, 0.0, v_bar, 0.0, 0.0
    while v > 0.0:
        a += ((-a_b if t >= dt else 0.0) - a) / tau * step
        v += a * step
        x += v * step
        t += step
    assert r - x >= d


def test_cube8_at_5p7_is_refused_naming_both_keys_and_the_bound():
    msg = _refusal(5.7)
    assert "formation.sensing_range_m = 5.7" in msg
    assert "controller.max_transient_speed_mps = 0" in msg
    x = math.floor(100.0 * chk.allowed_transient_speed(_cube8(5.7, allow=True))) / 100.0
    assert f"controller.max_transient_speed_mps ≤ {x:.2f} m/s" in msg
    assert "the range ≥ 6.93 m" in msg
    sc = _cube8(5.7, x)  # loads at the bound it names
    assert chk.safety_problems(sc) == []


def test_a_limit_too_fast_for_the_range_is_refused():
    msg = _refusal(5.7, 2.0)
    assert "controller.max_transient_speed_mps = 2" in msg and "≤ 1.1" in msg


def test_no_limit_fits_when_a_follower_starts_faster_than_the_range_allows():
    """cube8 at 5.7 m with follower 8 starting at 1.29 m/s: the start's v̄ = 2.75 m/s still
    fits (R_h = 4.46 m), but its transient alone is above the 1.19 m/s the range leaves."""
    data = load_scenario(CUBE8).to_toml_dict()
    data["formation"]["sensing_range_m"] = 5.7
    data["controller"]["max_transient_speed_mps"] = 0.5
    data["agent"][7]["velocity"] = [0.3, 1.25, 0.0]
    with pytest.raises(UnsafeScenarioError) as exc:
        parse_scenario(data, "variant.toml")
    msg = str(exc.value)
    assert "no controller.max_transient_speed_mps fits" in msg and "the range ≥ 6.00 m" in msg


def test_allow_unsafe_runs_it_with_a_warning(caplog):
    sc = _cube8(5.7, allow=True)
    assert sc.allow_unsafe and "controller.max_transient_speed_mps" in caplog.text


def test_the_limit_is_ignored_where_no_pair_comes_into_range():
    assert chk.closing_speed(_cube8(10.0, 0.3)) == chk.start_closing_speed(_cube8(10.0))


def test_a_non_cooperative_follower_needs_the_whole_span_sensed() -> None:
    """A follower with no filter has no speed rows, so no v_t bounds how fast it comes into
    range: below the span, cube8_rogue is refused naming the agent and the range, whatever
    v_t; at the span it loads."""
    data = load_scenario(ROOT / "scenarios" / "cube8_rogue.toml").to_toml_dict()
    data["controller"]["max_transient_speed_mps"] = 1.15
    data["formation"]["sensing_range_m"] = 5.7
    with pytest.raises(UnsafeScenarioError) as exc:
        parse_scenario(data, "rogue.toml")
    msg = str(exc.value)
    assert "\n" not in msg and "cooperative = false" in msg and "formation.sensing_range_m" in msg
    data["formation"]["sensing_range_m"] = round(tc.span(_cube8(10.0)) + 0.01, 2)
    assert chk.range_problem(parse_scenario(data, "rogue.toml")) is None
