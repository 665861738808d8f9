"""The dcbf trust region (offboard.safety.dcbf.trust, docs/safety.md 5f): its table bounds
the real inner-loop model's error for jumps inside the box, the tight rows carry
ē(J, a0) = ē_base + ē_model(J, b(a0)) and equal the rows made with that margin, the step
falls back to the full rows when the tight QP needs slack, and the scenario keys are
validated (one line naming the key)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from offboard.safety.base import SafetyInput
from offboard.safety.dcbf.filter import DcbfFilter, input_set_of
from offboard.safety.dcbf.kernel import dcbf_rows_kernel
from offboard.safety.dcbf.model import LagCoefficients
from offboard.safety.dcbf.step_kernel import P_ACCEL_ERR, P_ALT_ERR
from offboard.safety.dcbf.trust import A0_BINS, lag_model_error, model_error_table
from offboard.safety.rcbf.clf_rcbf import ClfTerms
from swarm_common.enums import QPStatus
from swarm_common.scenario.model import ScenarioError, load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[3]
SC = load_scenario(ROOT / "scenarios" / "dense_cube1p5.toml")
VEH, CTL = SC.vehicle, SC.controller
DT = SC.control_dt
T = VEH.tau_rollpitch_s + DT
USET = input_set_of(CTL, VEH)
NO_CLF = ClfTerms(V=0.0, lfv=0.0, lgv=np.zeros(3), u_nom=np.zeros(3))
BOX = np.full(3, 8.0)


def _filter() -> DcbfFilter:
    f = DcbfFilter(CTL, -BOX, BOX, np.zeros(SC.n, dtype=bool))
    f.configure(VEH, DT)
    return f


@pytest.mark.parametrize("jump", [0.25, 0.5])
def test_table_bounds_the_real_model_for_random_jumps_in_the_box(jump: float) -> None:
    """Random a0 in each bin and u anywhere in the box a0 ± J (not the grid's points):
    the real inner-loop model's error stays within the table, which grows with the bin."""
    table = model_error_table(VEH, USET, T, jump)
    assert list(table) == sorted(table) and len(table) == len(A0_BINS)
    lag = LagCoefficients.of(np.array([VEH.tau_rollpitch_s] * 2 + [VEH.tau_thrust_s]), T)
    rng = np.random.default_rng(7)
    worst = np.zeros(len(A0_BINS))
    n = 0
    while n < 150:
        b = int(rng.integers(len(A0_BINS)))
        a0 = rng.uniform(-A0_BINS[b], A0_BINS[b], 3)
        u = a0 + rng.uniform(-jump, jump, 3)
        if not (USET.contains(a0) and USET.contains(u)):
            continue
        n += 1
        worst[b] = max(worst[b], lag_model_error(a0, u, VEH, lag))
    assert np.all(worst <= np.array(table))
    assert worst.max() > 0.2 * max(table)  # the samples did reach the table's scale


def test_level_doubles_while_the_box_binds_and_gives_up_past_the_last() -> None:
    f = _filter()
    tr = f.trust
    assert tr is not None and tr.jump == CTL.dcbf_trust_jump_mps2 == 0.25
    z = np.zeros(3)
    assert tr.level(z, z) == 0.25
    assert tr.level(z, np.array([0.3, 0.0, 0.0])) == 0.5  # 1.5 × 0.3 = 0.45
    assert tr.level(z, np.array([0.0, -1.0, 0.0])) == 2.0  # 1.5
    assert tr.level(z, np.array([0.0, 0.0, 1.5])) == 0.0  # 2.25 > 8 J = 2: full rows


def test_tight_rows_carry_the_trust_margin_and_the_main_rows_the_full_one() -> None:
    """One step through DcbfFilter.apply: the parameter is ē_base + ē_model(J, b(a0)) for
    a0 in the bin ‖a0‖∞ ≤ 1, the box is a0 ± J, and both row sets equal the rows of
    dcbf_rows_kernel made with their margin (the step's other acceleration is the
    broadcast one: first sample of the pair)."""
    f = _filter()
    a0 = np.array([0.6, -0.3, 0.2])
    dp, dv = np.array([[1.4, 0.2, -0.1]]), np.array([[-0.2, 0.0, 0.1]])
    x = SafetyInput(
        clf=NO_CLF, w=np.zeros(3), z2=np.zeros(3), dp=dp, dv=dv, pairs=np.array([2]),
        lead_acc={}, a_real=a0, u_prev=a0.copy(), a_mean=a0, other_acc=np.zeros((1, 3)),
        full_share=np.array([False]), z1=None, floor_m=None,
    )
    f.apply(x)
    e_tight = CTL.dcbf_trust_error_mps2 + model_error_table(VEH, USET, T, 0.25)[1]
    prm = f.rows_state()[0]
    assert prm[P_ALT_ERR] == pytest.approx(e_tight, rel=1e-12)
    assert prm[P_ACCEL_ERR] == CTL.dcbf_accel_error_mps2
    assert 0.25 < e_tight < CTL.dcbf_accel_error_mps2
    assert f.tight_qp is not None
    assert np.allclose(f.tight_qp.lo_u[-3:], a0 - 0.25) and np.allclose(f.tight_qp.hi_u[-3:],
                                                                        a0 + 0.25)
    lag = f.lag
    assert lag is not None
    out = f.rows_out()
    for err, g, rhs in ((e_tight, out.g_alt, out.rhs_alt), (CTL.dcbf_accel_error_mps2, out.g,
                                                            out.rhs)):
        g_ref, r_ref = dcbf_rows_kernel(
            dp, dv, a0, a0, np.zeros((1, 3)), np.array([0.5]), np.array([CTL.d_safe_m]),
            lag.table, lag.sens3, lag.T, CTL.tau_safe_s, CTL.dcbf_gamma_lin,
            CTL.dcbf_gamma_cubic, err,
        )
        assert np.array_equal(g[:2], g_ref) and np.array_equal(rhs[:2], r_ref)
    # the smaller margin asks less of the command: the tight rows' right-hand sides
    assert np.all(out.rhs_alt[:2] < out.rhs[:2])


def _one_row_step(f: DcbfFilter, r_tight: float, r_full: float) -> tuple[np.ndarray, QPStatus]:
    """The rows u_x ≥ r (one per set) at a0 = u_prev = 0 (box ±0.25), u_nom = 0."""
    f.prepare_trust(np.zeros(3), np.zeros(3))
    out = f.rows_out()
    out.g[0], out.rhs[0] = (1.0, 0.0, 0.0), r_full
    out.g_alt[0], out.rhs_alt[0] = (1.0, 0.0, 0.0), r_tight
    res = f.solve_rows(np.zeros(3), NO_CLF, 1, 1.0, np.zeros(3), np.zeros(3), unheld=True)
    return res.u, res.qp_status


def test_the_tight_qp_answers_when_feasible_and_the_full_one_when_it_needs_slack() -> None:
    f = _filter()
    u, status = _one_row_step(f, 0.1, 0.4)
    assert status is QPStatus.SOLVED and u[0] == pytest.approx(0.1, abs=1e-6)
    assert np.all(np.abs(u) <= 0.25 + 1e-9)  # inside the box: the tight margin's assumption
    assert f.trust_counts.tolist() == [1, 0, 0]
    # the tight row asks u_x ≥ 0.6, outside the box ±0.25: σ > 0, so the full rows fly
    u, status = _one_row_step(f, 0.6, 0.9)
    assert status is QPStatus.SOLVED and u[0] == pytest.approx(0.9, abs=1e-6)
    assert f.trust_counts.tolist() == [1, 1, 0]


def test_without_the_keys_there_is_no_trust_region() -> None:
    sc = load_scenario(ROOT / "scenarios" / "cube8.toml")
    f = DcbfFilter(sc.controller, -BOX, BOX, np.zeros(sc.n, dtype=bool))
    f.configure(sc.vehicle, sc.control_dt)
    assert f.trust is None and f.tight_qp is None and f.rows_out().g_alt.shape == (0, 3)
    f.prepare_trust(np.zeros(3), np.ones(3))  # nothing to prepare
    assert f.rows_state()[0][P_ALT_ERR] == 0.0


@pytest.mark.parametrize(("keys", "message"), [
    ({"dcbf_trust_jump_mps2": -0.5}, "controller.dcbf_trust_jump_mps2 = -0.5: must be"),
    ({"dcbf_trust_jump_mps2": 0.0}, "controller.dcbf_trust_error_mps2 = 0.25: only read"),
    ({"dcbf_trust_error_mps2": 0.0}, "controller.dcbf_trust_jump_mps2 = 0.25: needs"),
    ({"dcbf_trust_error_mps2": 0.75}, "must be below controller.dcbf_accel_error_mps2"),
    ({"dcbf_trust_error_mps2": 0.1}, "above the margin controller.dcbf_trust_error_mps2"),
])
def test_bad_trust_keys_are_refused_in_one_line(keys: dict[str, float], message: str) -> None:
    with pytest.raises(ScenarioError, match=message) as exc:
        with_overrides(SC, controller=keys)
    assert "\n" not in str(exc.value)

