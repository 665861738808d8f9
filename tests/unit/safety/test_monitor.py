"""In-flight alarms (offboard.safety.monitor) on synthetic data, the fallback law, and the
alarm bits on the wire (docs/safety.md, "In-flight alarms and the fallback")."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from offboard.agent.fallback import BRAKED_MPS, HOLD_S, Fallback
from offboard.safety.monitor import MonitorConfig, SafetyMonitor, residual_bound
from offboard.safety.monitor_kernel import BEFORE, OUT, monitor_terms
from swarm_common import wire
from swarm_common.barrier import barrier
from swarm_common.enums import AgentAlarm

DT = 0.02  # s, 50 Hz
N = 5  # agent 0 is "us"; 1..4 the neighbours
CFG = MonitorConfig(bound_m=2.77, v_max_mps=30.0, persist=10, fallback_after=25,
                    tau_s=0.8, d_safe_m=0.5, range_m=10.0)


class World:
    """Five agents on a line 2 m apart moving at 1 m/s; our estimate has error ``err``."""

    def __init__(self, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.p0 = np.array([[2.0 * i, 0.0, 5.0] for i in range(N)])
        self.v = np.tile([1.0, 0.0, 0.0], (N, 1))

    def inputs(self, t: float, err: np.ndarray, sensed: np.ndarray | None = None) -> dict:
        p = self.p0 + self.v * t
        rel_p = p - p[0] + self.rng.normal(0.0, 0.02, (N, 3))  # sensing noise 2 cm
        rel_v = np.zeros((N, 3))
        fresh = np.ones(N, dtype=bool) if sensed is None else sensed.copy()
        fresh[0] = False
        est_p = p + self.rng.normal(0.0, 0.05, (N, 3))  # the others' estimates, 5 cm off
        return dict(z1=p[0] + err, z2=self.v[0].copy(), est_p=est_p,
                    have=np.arange(N) > 0, peers=np.arange(1, N), rel_p=rel_p, fresh=fresh,
                    sel=np.flatnonzero(fresh), pair_p=rel_p, pair_v=rel_v)


def run(errs: list[np.ndarray], seed: int = 0) -> list[AgentAlarm]:
    w, m = World(seed), SafetyMonitor(CFG, N)
    return [m.step(**w.inputs(k * DT, e)) for k, e in enumerate(errs)]


def test_bound_from_noise() -> None:
    # the 0.999 quantile of ‖e_i − e_j‖ for two N(0, σ² I₃) errors, by sampling (1e6 pairs;
    # the sampled quantile is within 1 % of the formula's)
    rng = np.random.default_rng(1)
    s0 = 0.3
    d = np.linalg.norm(rng.normal(0, s0, (1_000_000, 3)) - rng.normal(0, s0, (1_000_000, 3)),
                       axis=1)
    start = residual_bound(s0, 0.0, 0.0, 10.0) - 1.0
    assert abs(np.quantile(d, 0.999) - start) < 0.01 * start
    # the sensing term: 4 σ of a relative position measured at 10 m
    assert residual_bound(0.0, 0.005, 0.001, 10.0) == pytest.approx(1.0 + 4 * 0.015)


def test_consistent_estimate_raises_nothing() -> None:
    rng = np.random.default_rng(2)
    for seed in range(5):  # 30 s each: an estimate 0.3 m off (std per axis), sensing noise
        errs = [rng.normal(0.0, 0.3, 3) for _ in range(1500)]
        assert not any(run(errs, seed)), seed


def test_diverging_estimate_raises_residual_within_a_second() -> None:
    # consistent for 2 s, then an error growing at 10 m/s² ... 1 m/s: crossing the bound
    for rate in (10.0, 1.0):
        errs = [np.zeros(3)] * 100 + [np.array([rate * (k * DT), 0.0, 0.0])
                                      for k in range(1, 2000)]
        bits = run(errs)
        cross = next(k for k, e in enumerate(errs) if np.linalg.norm(e) > CFG.bound_m)
        first = next(k for k, b in enumerate(bits) if b & AgentAlarm.RESIDUAL)
        fb = next(k for k, b in enumerate(bits) if b & AgentAlarm.FALLBACK)
        assert 0 < (first - cross) * DT <= 1.0, rate
        assert 0 < (fb - cross) * DT <= 1.0, rate
        assert all(b & AgentAlarm.FALLBACK for b in bits[fb:])  # latched


def test_short_spike_is_not_an_alarm() -> None:
    # over the bound for fewer steps than the persistence window: nothing
    errs = [np.zeros(3)] * 50 + [np.array([5.0, 0, 0])] * (CFG.persist - 1) + [np.zeros(3)] * 50
    assert not any(run(errs))


def residual_oracle(z1: np.ndarray, est_p: np.ndarray, rel_p: np.ndarray, use: np.ndarray,
                    unseen: np.ndarray, range_m: float) -> float:
    """The residual in numpy (offboard.safety.monitor's docstring), NaN without a row."""
    r = np.linalg.norm(z1[None, :] - (est_p[use] - rel_p[use]), axis=1)
    lo = np.maximum(range_m - np.linalg.norm(est_p[unseen] - z1[None, :], axis=1), 0.0)
    both = np.concatenate([r, lo])
    return float(np.max(both)) if len(both) else math.nan


def terms(z1: np.ndarray, est: np.ndarray, rel: np.ndarray, usable: np.ndarray,
          fresh: np.ndarray, sel: np.ndarray, range_m: float,
          prev: np.ndarray | None = None,
          peers: np.ndarray | None = None) -> tuple[float, float, bool, np.ndarray]:
    """monitor_terms with the readable rows ``usable`` (N,) bool of the ``peers`` (all
    agents by default) and the last step's sensed set ``prev`` (N,) bool; returns the newly
    sensed set as (N,) bool. Checks the kept state: this call's set, marked and listed."""
    n = len(est)
    sel = np.asarray(sel, np.int64)
    prev = np.zeros(n, bool) if prev is None else prev
    mark = np.where(prev, BEFORE, OUT).astype(np.int8)
    before = np.flatnonzero(prev).astype(np.int64)
    listed = np.concatenate([before, np.full(n, -1, np.int64)])
    new_idx = np.full(max(len(sel), 1), -1, np.int64)
    peers = np.arange(n, dtype=np.int64) if peers is None else peers
    res, speed, n_new = monitor_terms(z1, np.array([3.0, 4.0, 0.0]), est, usable, peers, rel,
                                      fresh, sel, mark, listed, len(before), new_idx, range_m)
    now = np.zeros(n, bool)
    now[sel] = True
    assert np.array_equal(mark, np.where(now, BEFORE, OUT))
    assert list(listed[:len(sel)]) == list(sel)
    new = np.zeros(n, bool)
    new[new_idx[:n_new]] = True
    assert n_new == int(np.sum(new))  # each once
    return res, speed, n_new > 0, new


def test_unsensed_neighbour_inside_range_is_inconsistent() -> None:
    # nobody is sensed; the estimates put neighbours 2..8 m away (< R = 10 m): their true
    # distance is ≥ R, so the residual is at least R − 2 m for the nearest
    z1 = np.zeros(3)
    est = np.array([[0.0, 0, 0], [2.0, 0, 0], [4.0, 0, 0], [6.0, 0, 0], [8.0, 0, 0]])
    none, others = np.zeros(N, bool), np.arange(N) > 0
    res, speed, any_new, _ = terms(z1, est, np.zeros((N, 3)), others, none, [], 10.0)
    assert res == 8.0 and speed == 5.0 and not any_new
    # out of range in the estimates: no evidence either way
    assert terms(z1, est * 6, np.zeros((N, 3)), others, none, [], 10.0)[0] == 0.0
    # every usable neighbour is sensed (held, not fresh): no row counts
    assert math.isnan(terms(z1, est, est, others, none, [1, 2, 3, 4], 10.0)[0])


def test_residual_kernel_matches_numpy() -> None:
    # random rows, masks and sensed sets: the compiled residual against numpy (1e-12 m),
    # and the newly sensed pairs against the set difference
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(2, 12))
        z1 = rng.normal(0, 5, 3)
        est, rel = rng.normal(0, 5, (n, 3)), rng.normal(0, 5, (n, 3))
        have, fresh = rng.random(n) < 0.8, rng.random(n) < 0.5
        peer = rng.random(n) < 0.8  # only the peers' rows are read
        usable = have & peer
        sel = np.flatnonzero(rng.random(n) < 0.5)
        prev = rng.random(n) < 0.5
        was = prev.copy()
        sensed = np.zeros(n, bool)
        sensed[sel] = True
        want = residual_oracle(z1, est, rel, usable & fresh, usable & ~fresh & ~sensed, 6.0)
        peers = np.flatnonzero(peer).astype(np.int64)
        res, _, any_new, new = terms(z1, est, rel, have, fresh, sel, 6.0, prev, peers)
        assert (math.isnan(res) and math.isnan(want)) or abs(res - want) <= 1e-12
        # the peer table's whole rows (ẑ1 in the first three columns) give the same
        wide = np.hstack([est, rng.normal(0, 9, (n, 5))])
        res_wide = terms(z1, wide, rel, have, fresh, sel, 6.0, was.copy(), peers)[0]
        assert (math.isnan(res_wide) and math.isnan(want)) or abs(res_wide - want) <= 1e-12
        assert np.array_equal(new, sensed & ~was) and any_new == bool(np.any(new))
    # a NaN estimate in a counted row makes the residual NaN, as numpy's max does
    est = np.ones((3, 3))
    est[1, 0] = math.nan
    assert math.isnan(terms(np.zeros(3), est, np.zeros((3, 3)), np.ones(3, bool),
                            np.ones(3, bool), [], 6.0)[0])


def test_impossible_speed_is_a_residual() -> None:
    w, m = World(), SafetyMonitor(CFG, N)
    bits = []
    for k in range(CFG.persist + 1):
        x = w.inputs(k * DT, np.zeros(3))
        x["z2"] = np.array([0.0, 0.0, -40.0])
        bits.append(m.step(**x))
    assert not bits[CFG.persist - 2] and bits[-1] & AgentAlarm.RESIDUAL


def test_near_entry_only_for_a_late_close_newcomer() -> None:
    w, m = World(), SafetyMonitor(CFG, N)
    far = np.array([True, True, True, True, False])
    assert not m.step(**w.inputs(0.0, np.zeros(3), far))
    # agent 4 appears 0.4 m away closing at 2 m/s: h = 0.16 − 2·0.8·2·0.4 − 0.25 < 0
    x = w.inputs(DT, np.zeros(3), np.ones(N, bool))
    x["pair_p"][4] = [0.4, 0.0, 0.0]
    x["pair_v"][4] = [-2.0, 0.0, 0.0]
    assert barrier(x["pair_p"][4:], x["pair_v"][4:], 0.8, 0.5)[0] < 0
    assert m.step(**x) == AgentAlarm.NEAR_ENTRY
    # the next step it is no newcomer: no alarm although still close
    x2 = w.inputs(2 * DT, np.zeros(3), np.ones(N, bool))
    x2["pair_p"][4], x2["pair_v"][4] = x["pair_p"][4], x["pair_v"][4]
    assert not m.step(**x2)
    # a newcomer far away (h > 0): nothing
    m2 = SafetyMonitor(CFG, N)
    m2.step(**w.inputs(0.0, np.zeros(3), far))
    assert not m2.step(**w.inputs(DT, np.zeros(3), np.ones(N, bool)))


def test_fallback_brakes_holds_then_lands() -> None:
    # a point mass at 8 m/s, 10 m up, flown by the fallback's command (box ±3, ±8 m/s²)
    lo, hi = np.array([-3.0, -3.0, -8.0]), np.array([3.0, 3.0, 8.0])
    fb = Fallback(4.0, 3.0, lo, hi)
    fb.start(0.0)
    p, v = np.array([0.0, 0.0, 10.0]), np.array([8.0, 0.0, 0.0])
    dt, ps, vz = 0.002, [], []
    for k in range(int(40.0 / dt)):
        u = fb.command(k * dt, p, v)
        assert np.all(u >= lo - 1e-12) and np.all(u <= hi + 1e-12)
        v = v + u * dt
        p = p + v * dt
        if p[2] < 0.0:  # ground contact
            p[2], v[2] = 0.0, max(v[2], 0.0)
        ps.append(p.copy())
        vz.append(v[2])
    ps_a = np.array(ps)
    assert fb.hold_p is not None and fb.t_hold < 8.0 / 3.0 + 0.5  # braked at 3 m/s²
    # braking distance v²/(2a) = 10.7 m; it stays within 1 m of where it stopped
    assert np.max(ps_a[:, 0]) < 8.0**2 / 6.0 + 1.0
    k_hold = int(fb.t_hold / dt)
    k_desc = int((fb.t_hold + HOLD_S) / dt)
    assert np.max(np.abs(ps_a[k_hold:k_desc, 2] - 10.0)) < 0.2  # hovers while holding
    assert ps_a[-1, 2] < 0.1 and min(vz) > -1.0  # landed, descending at about 0.6 m/s
    assert fb.landed(40.0, float(p[2]))
    assert np.linalg.norm(v) < BRAKED_MPS


def test_alarm_bits_on_the_wire() -> None:
    s = wire.Status(3, 1, 0.02, "OFFBOARD", "dcbf", "solved", 55.0, 1.2, 0.3, "ok", 0)
    assert wire.roundtrip(s).alarms == 0  # type: ignore[union-attr]
    s.alarms = int(AgentAlarm.RESIDUAL | AgentAlarm.FALLBACK)
    back = wire.roundtrip(s)
    assert isinstance(back, wire.Status) and AgentAlarm(back.alarms) == (
        AgentAlarm.RESIDUAL | AgentAlarm.FALLBACK)
    # an older sender's record has no "alarm" key: decoded as no alarm
    d = msgpack.unpackb(wire.encode(s), raw=False)
    del d["alarm"]
    old = wire.decode(msgpack.packb(d, use_bin_type=True))
    assert isinstance(old, wire.Status) and old.alarms == 0


def _persist_reference(cfg, residual, speed, z1, state):
    """The persistence rule as it was written in Python before it was compiled:
    ``state`` = [over, under, raised, held, fallback]."""
    over_n, under_n, raised, held, fallback = state
    over = (residual > cfg.bound_m or not math.isfinite(speed) or speed > cfg.v_max_mps
            or not all(map(math.isfinite, z1)))
    if over:
        over_n, under_n = over_n + 1, 0
    elif math.isfinite(residual):
        over_n, under_n = 0, under_n + 1
    if not raised and over_n >= cfg.persist:
        raised = True
    elif raised and under_n >= cfg.persist:
        raised = False
    held = held + 1 if raised else 0
    if held >= cfg.fallback_after:
        fallback = True
    state[:] = [over_n, under_n, raised, held, fallback]
    return raised


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_persistence_agrees_with_the_python_rule(seed: int) -> None:
    """Random residuals around the bound (NaN among them), speeds (over the limit, inf,
    NaN) and estimates (NaN): RESIDUAL and the fallback step for step as the rule says."""
    from offboard.safety.monitor_kernel import CTR_FALLBACK, residual_persist

    cfg = MonitorConfig(2.77, 30.0, 10, 25, 0.4, 1.0, 6.0)
    ctr = np.zeros(5, dtype=np.int64)  # a monitor's counters
    rng = np.random.default_rng(seed)
    state: list = [0, 0, False, 0, False]
    raised_seen = 0
    for k in range(3000):
        burst = (k // 40) % 3 == 0  # spells over the bound, long enough to raise it
        residual = float(rng.uniform(2.8, 4.0) if burst else rng.uniform(0.0, 2.9))
        if rng.random() < 0.05:
            residual = math.nan
        speed = float(rng.choice([1.0, 5.0, 31.0, math.inf, math.nan],
                                 p=[0.9, 0.06, 0.02, 0.01, 0.01]))
        z1 = np.array([0.0, math.nan if rng.random() < 0.005 else 1.0, 2.0])
        got = residual_persist(ctr, residual, speed, z1, cfg.bound_m, cfg.v_max_mps,
                               cfg.persist, cfg.fallback_after)
        want = _persist_reference(cfg, residual, speed, z1, state)
        assert got == want and bool(ctr[CTR_FALLBACK]) == state[4], (seed, k)
        raised_seen += got
    assert raised_seen > 0


def test_the_monitors_one_call_is_its_terms_then_its_persistence() -> None:
    """monitor_step gives what monitor_terms and then residual_persist give, state and all,
    on random steps (NaN estimates among them)."""
    from offboard.safety.monitor_kernel import monitor_step, monitor_terms, residual_persist

    rng = np.random.default_rng(9)
    n = 6
    peers = np.array([0, 2, 3, 5], dtype=np.int64)

    def state() -> list[np.ndarray]:  # mark, list, new, counters
        return [np.zeros(n, np.int8), np.zeros(n, np.int64), np.zeros(n, np.int64),
                np.zeros(5, np.int64)]

    a, b = state(), state()
    n_prev = 0
    for k in range(2000):
        z1 = rng.normal(0.0, 2.0, 3)
        if rng.random() < 0.01:
            z1[1] = math.nan
        z2 = rng.normal(0.0, 3.0, 3) * (12.0 if rng.random() < 0.02 else 1.0)
        est = rng.normal(0.0, 3.0, (n, 3))
        rel = est - z1 + rng.normal(0.0, 2.0 if (k // 50) % 2 else 0.3, (n, 3))
        have, fresh = rng.random(n) < 0.8, rng.random(n) < 0.7
        sel = np.flatnonzero(rng.random(n) < 0.5).astype(np.int64)
        res, speed, new = monitor_terms(z1, z2, est, have, peers, rel, fresh, sel, *a[:2],
                                        n_prev, a[2], 6.0)
        raised = residual_persist(a[3], res, speed, z1, 2.77, 30.0, 10, 25)
        got = monitor_step(z1, z2, est, have, peers, rel, fresh, sel, *b[:2], n_prev, b[2],
                           6.0, b[3], 2.77, 30.0, 10, 25)
        n_prev = len(sel)
        assert (got[0] == res or (math.isnan(got[0]) and math.isnan(res))), k
        assert got[1:] == (new, raised), k
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)), k
