"""The rest spacing d* of the dcbf pair rows (offboard.safety.dcbf.liveness)."""

from __future__ import annotations

import numpy as np
import pytest

from offboard.safety.dcbf.liveness import rest_rows_hold, rest_spacing_m
from offboard.safety.dcbf.model import LagCoefficients

# cube8's [vehicle] and [controller] (scenarios/cube8.toml)
TAU_RP, TAU_F, DT, TAU_S, D = 0.15, 0.03, 0.02, 0.8, 0.5
CUBE8 = dict(tau_s=TAU_S, d_safe=D, gamma1=0.3, gamma3=0.05, accel_err=2.0)


def test_cube8_rest_spacing_lies_between_the_formed_and_the_unformed_cubes() -> None:
    """Measured (docs/safety.md): a 3 m cube forms, a 2.5 m one never does."""
    d = rest_spacing_m(TAU_RP, TAU_F, DT, **CUBE8)
    assert 2.5 < d < 3.0


def test_rows_hold_exactly_from_the_rest_spacing_on() -> None:
    """Dense sampling (5 mm) of both axes: the distances where the rows hold at rest are
    one interval [d*, ∞), d* to within the 1 mm tolerance."""
    lag = LagCoefficients.of(np.array([TAU_RP, TAU_RP, TAU_F]), TAU_RP + DT)
    d_star = rest_spacing_m(TAU_RP, TAU_F, DT, **CUBE8)
    first = []
    for axis in (0, 1, 2):
        ds = np.arange(D + 1e-3, 6.0, 5e-3)
        ok = np.array([rest_rows_hold(float(x), axis, lag, **CUBE8) for x in ds])
        i = int(np.argmax(ok))
        assert ok[i] and ok[i:].all() and not ok[:i].any()
        first.append(ds[i])
    assert max(first) == pytest.approx(d_star, abs=5e-3 + 1e-3)


def test_without_an_error_margin_agents_can_hover_just_outside_d_safe() -> None:
    """ē = 0: at rest ḣ_T = 0 and α(h) ≥ 0 for h ≥ 0, so d* is D (to the tolerance)."""
    d = rest_spacing_m(TAU_RP, TAU_F, DT, **{**CUBE8, "accel_err": 0.0})
    assert D <= d <= D + 2e-3


@pytest.mark.parametrize("key, lo, hi", [("accel_err", 0.5, 2.0), ("gamma1", 0.3, 1.0)])
def test_rest_spacing_falls_with_a_smaller_margin_or_a_steeper_alpha(
    key: str, lo: float, hi: float,
) -> None:
    """d* falls as ē falls (smaller margins) and as γ1 grows (α pays for them sooner)."""
    small = rest_spacing_m(TAU_RP, TAU_F, DT, **{**CUBE8, key: lo})
    large = rest_spacing_m(TAU_RP, TAU_F, DT, **{**CUBE8, key: hi})
    if key == "accel_err":
        assert small < large - 0.5
    else:
        assert large < small - 0.1


def test_no_alpha_means_no_rest_spacing() -> None:
    d = rest_spacing_m(TAU_RP, TAU_F, DT, **{**CUBE8, "gamma1": 0.0, "gamma3": 0.0},
                       d_max=100.0)
    assert d == float("inf")
