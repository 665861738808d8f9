"""The RCBF filter's compiled rows (offboard.safety.rcbf.kernel): the fused call against the chain
of calls it replaced, the rows against the numpy formulation, and the filter's inputs."""

import numpy as np
import pytest
from reference.clf_rows import rcbf_rows
from reference.close import assert_close

from offboard.safety.base import SafetyInput
from offboard.safety.pair_kernel import FULL_SHARE, SPLIT_SHARE
from offboard.safety.rcbf.clf_rcbf import barrier, tangential_term
from offboard.safety.rcbf.filter import RcbfFilter
from offboard.safety.rcbf.kernel import rcbf_filter_rows_kernel, rcbf_params, rcbf_rows_kernel
from swarm_common.scenario.model import load_scenario

TAU, D_SAFE, GAMMA, SIDE_GAIN, SIDE_H = 0.8, 0.5, 0.6, 0.7, 3.0


def _case(rng: np.random.Generator, m: int) -> tuple[np.ndarray, ...]:
    scale = 10.0 ** rng.uniform(-2, 1, size=(m, 1))
    dp = rng.normal(0, 1.0, (m, 3)) * scale
    dv = rng.normal(0, 1.0, (m, 3)) * scale
    lead = rng.random(m) < 0.3
    a_other = np.where(lead[:, None], rng.normal(0, 1.0, (m, 3)), 0.0)
    w = rng.normal(0, 0.3, 3)
    return dp, dv, lead, a_other, w


def _numpy_rows(dp, dv, w, a_other, share, h, margin=1e-3):
    """The numpy formulation the kernel replaced (einsum and h**3)."""
    base = 2.0 * np.einsum("ij,ij->i", dp, dv) + 2.0 * TAU * np.einsum("ij,ij->i", dv, dv)
    base += GAMMA * h**3
    nrm = np.maximum(np.sqrt(np.einsum("ij,ij->i", dp, dp)), 1e-6)
    n_hat = dp / nrm[:, None]
    rhs = -share * base / (2.0 * TAU * nrm) - np.einsum("ij,ij->i", n_hat, w[None, :] - a_other)
    return n_hat, rhs + margin


def test_fused_call_equals_the_chain_it_replaced() -> None:
    rng = np.random.default_rng(7)
    params = rcbf_params(TAU, D_SAFE, GAMMA, SIDE_GAIN, SIDE_H)
    for _ in range(500):
        m = int(rng.integers(0, 9))
        dp, dv, lead, a_other, w = _case(rng, m)
        n_hat, rhs, h, side = rcbf_filter_rows_kernel(dp, dv, lead, a_other, w, params)
        h_ref = barrier(dp, dv, TAU, D_SAFE)
        share = np.where(lead, FULL_SHARE, SPLIT_SHARE)
        n_ref, r_ref, _ = rcbf_rows(dp, dv, w, a_other, share, TAU, D_SAFE, GAMMA, h=h_ref)
        side_ref = tangential_term(dp, h_ref, SIDE_GAIN, SIDE_H)
        for got, ref in ((n_hat, n_ref), (rhs, r_ref), (h, h_ref), (side, side_ref)):
            # two implementations (the chain is partly numpy): within rounding (close.py)
            assert_close(got, ref)


def test_rows_agree_with_the_numpy_formulation_to_rounding() -> None:
    rng = np.random.default_rng(3)
    for _ in range(500):
        m = int(rng.integers(1, 9))
        dp, dv, lead, a_other, w = _case(rng, m)
        share = np.where(lead, 1.0, 0.5)
        h = barrier(dp, dv, TAU, D_SAFE)
        n_hat, rhs = rcbf_rows_kernel(dp, dv, w, a_other, share, h, TAU, GAMMA, 1e-3)
        n_ref, r_ref = _numpy_rows(dp, dv, w, a_other, share, h)
        np.testing.assert_allclose(n_hat, n_ref, rtol=1e-13, atol=1e-15)
        scale = np.abs(GAMMA * h**3 / (2 * TAU)) + np.abs(r_ref) + 1.0
        assert np.all(np.abs(rhs - r_ref) <= 1e-13 * scale)


def test_rows_bound_the_barrier_rate_by_finite_differences() -> None:
    """A control on a row's boundary gives ḣ = −share·… as the real double integrator
    moves: h along Δp̈ = u + w − a_j, differentiated numerically."""
    rng = np.random.default_rng(5)
    for _ in range(100):
        dp, dv, lead, a_other, w = _case(rng, 1)
        share = np.where(lead, 1.0, 0.5)
        h = barrier(dp, dv, TAU, D_SAFE)
        n_hat, rhs = rcbf_rows_kernel(dp, dv, w, a_other, share, h, TAU, GAMMA, 0.0)
        u = rhs[0] * n_hat[0] + np.cross(n_hat[0], rng.normal(0, 1, 3))  # n̂ᵀu = r
        acc = u + w - a_other[0]
        eps = 1e-6
        hp = barrier(dp + eps * dv + 0.5 * eps**2 * acc, dv + eps * acc, TAU, D_SAFE)[0]
        hm = barrier(dp - eps * dv + 0.5 * eps**2 * acc, dv - eps * acc, TAU, D_SAFE)[0]
        hdot = (hp - hm) / (2 * eps)
        # ḣ = 2ΔpᵀΔv + 2τ‖Δv‖² + 2τΔpᵀ(u + w − a_j) = (1 − share)·(… ) − share·γh³ on the row
        want = (1.0 - share[0]) * (2 * dp[0] @ dv[0] + 2 * TAU * dv[0] @ dv[0]) \
            - share[0] * GAMMA * h[0] ** 3
        assert abs(hdot - want) <= 1e-5 * (1.0 + abs(want))


def test_empty_pairs() -> None:
    params = rcbf_params(TAU, D_SAFE, GAMMA, SIDE_GAIN, SIDE_H)
    z = np.zeros((0, 3))
    n_hat, rhs, h, side = rcbf_filter_rows_kernel(z, z, np.zeros(0, bool), z, np.ones(3), params)
    assert n_hat.shape == (0, 3) and rhs.shape == (0,) and h.shape == (0,)
    assert np.array_equal(side, np.zeros(3))


def test_filter_takes_a_leaders_broadcast_acceleration_only() -> None:
    """The filter's rows against a leader use its broadcast a*; against a follower, and
    against a leader with no broadcast, zero."""
    ctl = load_scenario("scenarios/cube8.toml").controller
    lo, hi = np.full(3, -3.0), np.full(3, 3.0)
    leaders = np.array([True, False, False, True])
    filt = RcbfFilter(ctl, lo, hi, leaders)
    rng = np.random.default_rng(2)
    dp, dv = rng.normal(0, 1.5, (3, 3)), rng.normal(0, 1.0, (3, 3))
    pairs = np.array([0, 1, 3])
    a_lead = np.array([0.3, -0.2, 0.1])
    x = SafetyInput(None, np.zeros(3), np.zeros(3), dp, dv, pairs,  # type: ignore[arg-type]
                    {0: a_lead, 1: np.ones(3)})
    got = filt._other_accel(x, leaders[pairs].tolist())
    assert np.array_equal(got, np.array([a_lead, np.zeros(3), np.zeros(3)]))


def test_rows_of_different_lengths_are_refused() -> None:
    """The rows kernel reads its arrays without bounds checks: the wrapper refuses rows of
    different lengths."""
    rng = np.random.default_rng(4)
    dp, dv, _lead, a_other, w = _case(rng, 4)
    share = np.full(4, 0.5)
    for args in ((dp, dv[:3], w, a_other, share), (dp, dv, w, a_other[:2], share),
                 (dp, dv, w, a_other, share[:1])):
        with pytest.raises(ValueError, match="length"):
            rcbf_rows(*args, TAU, D_SAFE, GAMMA)
    with pytest.raises(ValueError, match="length"):
        rcbf_rows(dp, dv, w, a_other, share, TAU, D_SAFE, GAMMA, h=np.zeros(5))
