"""The fallback's landing (offboard.agent.fallback): it reaches the ground against ground
effect, touching down slower than a ground strike, and it does not descend onto an agent
that it senses below it."""

from __future__ import annotations

import numpy as np

from offboard.agent.fallback import Fallback
from offboard.agent.landing import LANDED_Z

LO, HI = np.array([-3.0, -3.0, -8.0]), np.array([3.0, 3.0, 8.0])
STRIKE_MPS = 0.5  # gcs.report.verdict's ground strike speed
DT = 0.002


def _ground_effect(z: float) -> float:
    """An upward push that grows near the ground (m/s²): 1.2 at 0, none above 0.5 m."""
    return 1.2 * max(0.0, 1.0 - z / 0.5)


def _fly(fb: Fallback, p: np.ndarray, seconds: float, other: np.ndarray | None = None):
    """A lagged point mass (τ 0.15 s) flown by the fallback; ``other`` a fixed agent it
    senses. Returns the positions and the vertical speed at each ground contact."""
    v, a = np.zeros(3), np.zeros(3)
    ps, touch = [], []
    for k in range(int(seconds / DT)):
        t = k * DT
        below = None if other is None else (other - p)[None, :]
        u = fb.command(t, p, v, below)
        a = a + (u - a) * DT / 0.15
        acc = a + np.array([0.0, 0.0, _ground_effect(p[2])])
        v = v + acc * DT
        p = p + v * DT
        if p[2] <= 0.0:  # ground contact
            if v[2] < 0.0:
                touch.append(-v[2])
            p[2], v[2] = 0.0, 0.0
        ps.append(p.copy())
    return np.array(ps), touch


def test_the_fallback_lands_against_ground_effect_below_the_strike_speed():
    fb = Fallback(4.0, 3.0, LO, HI)
    fb.start(0.0)
    ps, touch = _fly(fb, np.array([0.0, 0.0, 3.0]), 20.0)
    assert touch and max(touch) < STRIKE_MPS
    assert ps[-1, 2] < LANDED_Z and fb.landed(20.0, float(ps[-1, 2]))
    # hovering in ground effect was what held the pad's-altitude PD up: still it stays
    # within its hold point's column
    assert np.max(np.hypot(ps[:, 0], ps[:, 1])) < 0.05


def test_the_fallback_does_not_land_on_an_agent_below_it():
    clear = 1.0
    fb = Fallback(4.0, 3.0, LO, HI, clear_m=clear)
    fb.start(0.0)
    other = np.array([0.3, 0.0, 0.0])  # landed 0.3 m to the side of the column
    ps, _ = _fly(fb, np.array([0.0, 0.0, 3.0]), 25.0, other)
    d_xy = np.hypot(ps[:, 0] - other[0], ps[:, 1] - other[1])
    low = ps[:, 2] < 1.0
    assert low.any()  # it did land in the end
    assert np.min(d_xy[low]) >= clear - 0.05  # beside it, not on it
    assert ps[-1, 0] < 0.0  # it moved away from the other's side
    # without the clearance it lands in its column, 0.3 m from the other
    fb0 = Fallback(4.0, 3.0, LO, HI)
    fb0.start(0.0)
    ps0, _ = _fly(fb0, np.array([0.0, 0.0, 3.0]), 25.0, other)
    assert np.hypot(*(ps0[-1, :2] - other[:2])) < 0.35
