"""The dcbf filter's fused rows kernel (offboard.safety.dcbf.step_kernel) against the chain of
calls it replaced: barrier, its minimum, the deadlock breaker, the budget share, the other
agents' accelerations, the pair rows and the ground rows, each through its public function
(those are checked against their numpy formulations in test_dcbf_kernel.py and against
finite differences in test_dcbf.py). The fused call must give the same rows, step after
step (the per-index state evolves inside both), so the filter is the same filter: the
flags exactly, the floats within rounding (tests/reference/close.py; the chain's public
functions are partly numpy formulations, a second implementation)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from reference.close import assert_close
from reference.dcbf_rows import dcbf_rows, ground_rows

from offboard.safety.dcbf.kernel import other_term_kernel
from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.step_kernel import (
    GroundInput,
    OwnMotion,
    PairRows,
    RowsOut,
    RowsState,
    dcbf_filter_rows_into,
    dcbf_params,
)
from offboard.safety.rcbf.clf_rcbf import barrier, tangential_term

TAU = np.array([0.15, 0.15, 0.03])
N = 9  # agents in the scenario (per-index state)
DT = 0.02
P = dict(tau_s=0.25, d_safe=0.6, gamma1=2.0, gamma3=0.5, accel_err=0.4, side_gain=0.8,
         side_h=0.6, dt=DT, smooth=0.5, ground_gamma=2.0, ground_err=1.0)


def _chain(
    p: dict[str, float], lag: LagCoefficients, dp: np.ndarray, dv: np.ndarray, pairs: np.ndarray,
    full: np.ndarray, predicted: np.ndarray, margin: np.ndarray, other_acc: np.ndarray,
    own: np.ndarray, floor: float | None, z: float, vz: float, state: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The calls DcbfFilter.apply made before the fused kernel, in their order."""
    a_real, u_prev, a_mean, w_safe = own
    h = barrier(dp, dv, p["tau_s"], p["d_safe"])
    h_min = float(h.min()) if len(h) else float("inf")
    side = tangential_term(dp, h, p["side_gain"], p["side_h"])
    share = np.where(full, 1.0, 0.5)
    other = other_term_kernel(pairs, predicted, dv, other_acc, w_safe, a_mean, DT,
                              p["smooth"], *state)
    g, rhs = dcbf_rows(dp, dv, a_real, u_prev, other, share, lag, p["tau_s"],
                       p["d_safe"] + margin, p["gamma1"], p["gamma3"], p["accel_err"])
    if floor is not None:
        gg, rg = ground_rows(z, vz, float(a_real[2]), float(w_safe[2]), floor, lag,
                             p["tau_s"], p["ground_gamma"], p["ground_err"])
        g, rhs = np.concatenate([g, gg]), np.concatenate([rhs, rg])
    return g, rhs, h_min, side


def _fused(
    rows: PairRows, own: OwnMotion, ground: GroundInput, params: np.ndarray,
    lag: LagCoefficients, state: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """dcbf_filter_rows_into into NaN-filled buffers with room to spare: (g, r, h_min,
    sidestep) as the rows written. The buffers' rows past K must stay as they were."""
    g_buf, r_buf = np.full((2 * N + 4, 3), np.nan), np.full(2 * N + 4, np.nan)
    side = np.full(3, np.nan)
    k, h_min = dcbf_filter_rows_into(rows, own, ground, _rows_state(params, lag, state),
                                     RowsOut(g_buf, r_buf, side))
    assert np.isnan(g_buf[k:]).all() and np.isnan(r_buf[k:]).all()
    return g_buf[:k], r_buf[:k], h_min, side


def _rows_state(params: np.ndarray, lag: LagCoefficients, state: list[np.ndarray]) -> RowsState:
    return RowsState(params, lag.table, lag.sens3, *state)


def _state() -> list[np.ndarray]:
    return [np.zeros((N, 3)), np.zeros(N, dtype=bool), np.zeros((N, 3)),
            np.zeros(N, dtype=bool)]


@pytest.mark.parametrize("side_gain", [0.8, 0.0])
def test_fused_rows_equal_the_chain_of_calls_step_after_step(side_gain: float) -> None:
    rng = np.random.default_rng(5)
    lag = LagCoefficients.of(TAU, 0.15 + DT)
    p = {**P, "side_gain": side_gain}
    params = dcbf_params(**p, horizon=lag.T)
    s_chain, s_fused = _state(), _state()
    for step in range(400):
        m = int(rng.integers(0, N))
        pairs = rng.permutation(N)[:m].astype(np.int64)
        dp = rng.normal(0.0, 1.5, (m, 3))
        dv = rng.normal(0.0, 1.0, (m, 3))
        full = rng.random(m) < 0.3
        predicted = rng.random(m) < 0.2
        margin = np.where(predicted, rng.random(m) * 0.3, 0.0)
        other_acc = rng.normal(0.0, 2.0, (m, 3))
        own = rng.normal(0.0, 2.0, (4, 3))
        floor = None if step % 3 == 0 else 0.5
        z, vz = float(rng.uniform(0.0, 3.0)), float(rng.normal())
        want = _chain(p, lag, dp, dv, pairs, full, predicted, margin, other_acc, own, floor,
                      z, vz, s_chain)
        got = _fused(
            PairRows(dp, dv, pairs, full, predicted, margin, other_acc), OwnMotion(*own),
            GroundInput(floor is not None, z, vz, 0.0 if floor is None else floor), params,
            lag, s_fused,
        )
        assert_close(got[0], want[0], step)
        assert_close(got[1], want[1], step)
        assert_close(got[2], want[2], step)  # inf (no pair) equal to inf
        assert_close(got[3], want[3], step)
        for a, b in zip(s_fused, s_chain, strict=True):
            if a.dtype == np.bool_:
                assert np.array_equal(a, b), step
            else:
                assert_close(a, b, step)


def test_fused_rows_report_a_nan_barrier_as_numpy_does() -> None:
    """A non-finite pair makes h_min nan (numpy's min), so the QP's guard sees it."""
    lag = LagCoefficients.of(TAU, 0.15 + DT)
    params = dcbf_params(**P, horizon=lag.T)
    dp = np.array([[1.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    dv = np.zeros((2, 3))
    z3 = np.zeros(3)
    got = _fused(
        PairRows(dp, dv, np.array([1, 2], dtype=np.int64), np.zeros(2, dtype=bool),
                 np.zeros(2, dtype=bool), np.zeros(2), np.zeros((2, 3))),
        OwnMotion(z3, z3, z3, z3), GroundInput(False, 0.0, 0.0, 0.0), params, lag, _state(),
    )
    assert math.isnan(got[2])
    assert got[0].shape == (4, 3) and not np.isfinite(got[1][1])


def test_small_buffers_are_refused_before_the_state_changes() -> None:
    """Buffers smaller than the K rows raise, and the per-index state is left as it was."""
    rng = np.random.default_rng(9)
    lag = LagCoefficients.of(TAU, 0.15 + DT)
    params = dcbf_params(**{**P, "side_gain": 0.4}, horizon=lag.T)
    state = _state()
    m = 3
    args = (PairRows(rng.normal(0.0, 1.5, (m, 3)), rng.normal(0.0, 1.0, (m, 3)),
                     np.arange(m, dtype=np.int64), np.zeros(m, bool), np.zeros(m, bool),
                     np.zeros(m), rng.normal(0.0, 2.0, (m, 3))),
            OwnMotion(*rng.normal(0.0, 2.0, (4, 3))), GroundInput(True, 1.0, 0.0, 0.5),
            _rows_state(params, lag, state))
    for g_rows, r_rows in ((2 * m + 1, 2 * m + 2), (2 * m + 2, 2 * m + 1)):
        with pytest.raises(ValueError, match="smaller"):
            dcbf_filter_rows_into(*args, RowsOut(np.zeros((g_rows, 3)), np.zeros(r_rows),
                                                 np.zeros(3)))
        assert not state[1].any() and not state[3].any()
    k, _ = dcbf_filter_rows_into(*args, RowsOut(np.zeros((2 * m + 2, 3)),
                                                np.zeros(2 * m + 2), np.zeros(3)))
    assert k == 2 * m + 2 and state[1][:m].all()  # the same call with room: state updated
