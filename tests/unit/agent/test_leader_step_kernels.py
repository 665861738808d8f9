"""The leader's command and one-period prediction (offboard.agent.leader.leader_control_kernel,
leader_prediction_kernel) against the numpy formulation they replaced: the same values
within rounding (tests/reference/close.py: two implementations), the signs of zeros and
NaN exactly, on random states; and the command driving a double
integrator onto a moving reference (so a wrong gain or sign fails)."""

from __future__ import annotations

import numpy as np
import pytest
from reference.close import assert_close

from offboard.agent.leader import leader_control_kernel, leader_prediction_kernel

TAU, KP, KD = 0.08, 4.0, 3.0


def control(*args: object) -> np.ndarray:
    """leader_control_kernel into a new (3,) array (NaN first: every element written)."""
    out = np.full(3, np.nan)
    leader_control_kernel(*args, out)
    return out


def predict(*args: object) -> tuple[np.ndarray, np.ndarray]:
    """leader_prediction_kernel into a new (2,3) array."""
    out = np.full((2, 3), np.nan)
    leader_prediction_kernel(*args, out)
    return out[0], out[1]


def control_numpy(ref: np.ndarray, p: np.ndarray, v: np.ndarray, d_hat: np.ndarray,
                  tau: float, kp: float, kd: float, lo: np.ndarray,
                  hi: np.ndarray) -> np.ndarray:
    a_ff = ref[6:9] + tau * ref[9:12]
    u = a_ff - d_hat + kp * (ref[0:3] - p) + kd * (ref[3:6] - v)
    return np.clip(u, lo, hi)


def prediction_numpy(p: np.ndarray, v: np.ndarray, u_mean: np.ndarray, d_hat: np.ndarray,
                     dt: float) -> tuple[np.ndarray, np.ndarray]:
    a = u_mean + d_hat
    return p + v * dt + 0.5 * a * dt**2, v + a * dt


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """NaNs where the other has them, zeros of the same sign, the rest within rounding
    (tests/reference/close.py)."""
    assert_close(a, b)
    zero = (a == 0.0) & (b == 0.0)
    return bool(np.array_equal(np.isnan(a), np.isnan(b))
                and np.array_equal(np.signbit(a[zero]), np.signbit(b[zero])))


def test_control_equals_the_numpy_formulation() -> None:
    rng = np.random.default_rng(11)
    lo, hi = np.array([-4.0, -4.0, -6.0]), np.array([4.0, 4.0, 3.0])
    for i in range(3000):
        ref, p, v, d = (rng.normal(0, 3, 12), rng.normal(0, 3, 3), rng.normal(0, 2, 3),
                        rng.normal(0, 1, 3))
        if i % 10 == 0:  # zeros of both signs and a NaN now and then
            ref[rng.integers(0, 12)] = -0.0
            p[rng.integers(0, 3)] = np.nan if i % 30 == 0 else 0.0
            d[:] = -0.0
        got = control(ref, p, v, d, TAU, KP, KD, lo, hi)
        assert _same(got, control_numpy(ref, p, v, d, TAU, KP, KD, lo, hi)), i


@pytest.mark.full
def test_prediction_equals_the_numpy_formulation() -> None:
    rng = np.random.default_rng(12)
    for i in range(3000):
        p, v, u, d = (rng.normal(0, 5, 3) for _ in range(4))
        dt = float(rng.choice([0.02, 0.01, 1 / 30, 0.005]))
        if i % 10 == 0:
            v[:] = -0.0
        got = predict(p, v, u, d, dt)
        want = prediction_numpy(p, v, u, d, dt)
        assert _same(got[0], want[0]) and _same(got[1], want[1]), i


def test_command_tracks_a_moving_reference() -> None:
    """A double integrator under the command (no lag, no disturbance) follows a ramp
    reference to within a millimetre after 5 s; the clip bounds the command."""
    dt, lo, hi = 0.002, np.full(3, -5.0), np.full(3, 5.0)
    p, v = np.array([1.0, -1.0, 0.5]), np.zeros(3)
    vel = np.array([0.3, 0.1, -0.2])
    for k in range(2500):
        t = k * dt
        ref = np.concatenate([vel * t, vel, np.zeros(6)])
        u = control(ref, p, v, np.zeros(3), 0.0, KP, KD, lo, hi)
        assert np.all(u >= lo) and np.all(u <= hi)
        p, v = predict(p, v, u, np.zeros(3), dt)
    assert np.allclose(p, vel * 2500 * dt, atol=1e-3)
