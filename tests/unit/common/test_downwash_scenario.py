"""``controller.dcbf_vertical_scale`` κ at load and in the run's metrics (docs/safety.md
§4c): the key's validation, the load-time checks that use D along z (start inside the
ellipsoidal safe set, sensing range), the liveness warning's rest spacing, the metrics'
and the monitor's barrier, and the shipped scenarios/cube8_downwash.toml."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from gcs.mission.preflight import liveness_problem
from gcs.mission.run_output import safety_spec
from offboard.safety.dcbf.liveness import rest_spacing_m
from offboard.safety.monitor import monitor_config
from swarm_common.scenario import safety_check as chk
from swarm_common.scenario.files import ScenarioError
from swarm_common.scenario.model import (
    UnsafeScenarioError,
    load_scenario,
    parse_scenario,
    with_overrides,
)

CUBE8 = ROOT / "scenarios" / "cube8.toml"
DOWNWASH = ROOT / "scenarios" / "cube8_downwash.toml"


def _cube8_text(line: str) -> str:
    text = CUBE8.read_text()
    anchor = "dcbf_cone_sides = 8"
    assert text.count(anchor) == 1
    return text.replace(anchor, f"{anchor}\n{line}")


@pytest.mark.parametrize("value", ["0.99", "0.0", "-2", "10.5", '"two"', "nan", "true"])
def test_a_bad_value_is_one_line_naming_the_key(value: str, tmp_path: Path) -> None:
    f = tmp_path / "x.toml"
    f.write_text(_cube8_text(f"dcbf_vertical_scale = {value}"))
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    msg = str(err.value)
    assert "controller.dcbf_vertical_scale" in msg and "\n" not in msg


def test_default_is_the_sphere_and_the_shipped_scenario_sets_it() -> None:
    assert load_scenario(CUBE8).controller.dcbf_vertical_scale == 1.0
    sc = load_scenario(DOWNWASH)  # loads: no load-time assumption broken
    assert sc.controller.dcbf_vertical_scale == 1.5
    assert chk.safety_problems(sc) == []
    assert liveness_problem(sc, "dcbf") is None
    assert safety_spec(sc).vertical_scale == 1.5
    assert monitor_config(sc).vertical_scale == 1.5
    assert safety_spec(load_scenario(CUBE8)).vertical_scale == 1.0


def test_start_outside_the_ellipsoid_is_refused_with_the_key() -> None:
    """cube8's agents 3 and 4 start stacked 2.2 m apart, closing at 1.2 m/s: inside the
    safe set of the sphere and of κ = 1.5, outside that of κ = 2 (h = 0.616/κ² − D²)."""
    base = load_scenario(CUBE8, allow_unsafe=True)
    for kappa, bad in ((1.0, False), (1.5, False), (2.0, True)):
        sc = with_overrides(base, controller={"dcbf_vertical_scale": kappa})
        line = chk.start_problem(sc)
        assert (line is not None) is bad
        if bad:
            assert line is not None and "controller.dcbf_vertical_scale = 2" in line
            assert f"h = {0.616 / kappa**2 - 0.25:.2f} m²" in line
    data = base.to_toml_dict()
    data["controller"]["dcbf_vertical_scale"] = 2.0
    with pytest.raises(UnsafeScenarioError, match="dcbf_vertical_scale"):
        parse_scenario(data, "x")  # refused without --allow-unsafe


def test_sensing_range_uses_the_vertical_semi_axis() -> None:
    """R_h and R_b take κD: a head-on vertical pair closing at v̄ has ellipsoidal h = 0 at
    τv̄ + √(τ²v̄² + κ²D²) (checked on the barrier itself), and must stop before κD."""
    base = load_scenario(CUBE8, allow_unsafe=True)
    v_bar, a_b = chk.closing_speed(base), chk.braking_accel(base)
    r1, b1 = chk.entry_range(base, v_bar), chk.stop_range(base, v_bar, a_b)
    sc = with_overrides(base, controller={"dcbf_vertical_scale": 3.0})
    r3, b3 = chk.entry_range(sc, v_bar), chk.stop_range(sc, v_bar, a_b)
    t, d = base.controller.tau_safe_s, base.controller.d_safe_m
    assert r3 == pytest.approx(t * v_bar + math.sqrt((t * v_bar) ** 2 + 9 * d * d))
    assert r3 > r1 and b3 == pytest.approx(b1 + 2 * d)
    p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, r3]])
    v = np.array([[0.0, 0.0, v_bar], [0.0, 0.0, 0.0]])  # closing head-on, vertically
    assert chk.pair_barriers(p, v, t, d, 3.0)[0, 1] == pytest.approx(0.0, abs=1e-9)
    # a range between the two needs (set past the loader, whose graph check wants more)
    mid = 0.5 * (max(r1, b1) + max(r3, b3))
    small = replace(sc, formation=replace(sc.formation, sensing_range_m=mid))
    line = chk.range_problem(small)
    assert line is not None and "dcbf_vertical_scale = 3" in line
    sphere = replace(small, controller=replace(small.controller, dcbf_vertical_scale=1.0))
    # the sphere passes the braking part; only the in-flight entries (§5i) remain
    rest = chk.range_problem(sphere)
    assert rest is None or "pairs come into range in flight" in rest


def test_rest_spacing_grows_vertically_only() -> None:
    """The liveness check's d*: κ = 1 as before; with κ the horizontal d* is unchanged
    and the vertical one grows (cube8's 4 m vertical edge: fits κ = 1.5, not κ = 2)."""
    def d_star(kappa: float | None = None, axes: tuple[int, ...] = (0, 2)) -> float:
        extra = {} if kappa is None else {"vertical_scale": kappa}
        return rest_spacing_m(0.15, 0.03, 0.02, 0.8, 0.5, 0.3, 0.05, 2.0, axes=axes, **extra)

    assert d_star(1.0) == d_star()
    hor = [d_star(k, (0,)) for k in (1.0, 2.0)]
    ver = [d_star(k, (2,)) for k in (1.0, 1.5, 2.0)]
    assert hor[0] == hor[1]
    assert ver[0] < ver[1] < 4.0 < ver[2]
    sc = with_overrides(load_scenario(CUBE8, allow_unsafe=True),
                        controller={"dcbf_vertical_scale": 2.0})
    line = liveness_problem(sc, "dcbf")
    assert line is not None and "dcbf_vertical_scale = 2" in line
