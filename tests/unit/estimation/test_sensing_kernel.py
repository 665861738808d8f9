"""The compiled sensing (offboard.estimation.sensing_kernel) against the numpy formulation it
replaced,
on random swarms: the same measurements within rounding for every agent in range (one out of
range is invalid and carries its distance only) (tests/reference/close.py: two
implementations; numpy's einsum sums rows of three as the kernel does,
``(a0 b0 + a2 b2) + a1 b1``, on some builds only), the same validity masks, and the same
draws from the seeded generator (same shapes, same order), so a seed gives the same noise.
Copies and negations (the dropout hold, the pair rows) are exact in any implementation and
are compared bit for bit.

The oracles below are the previous numpy implementations of ``Sensor.measure`` and
``DropoutHold.pairs``, kept verbatim but for taking the draws / state as arguments.
"""

from __future__ import annotations

import copy
import threading

import numpy as np
import pytest
from reference.close import assert_close

from offboard.estimation.sensing import DropoutHold, Measurements, Sensor
from swarm_common.scenario.model import SensingConfig


def _dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)




def measure_numpy(
    p: np.ndarray, v: np.ndarray, i: int, rng: np.random.Generator, sig: tuple[float, ...],
    rng_m: float, dropout: float,
) -> tuple[np.ndarray, ...]:
    n = len(p)
    rel = p - p[i]
    relv = v - v[i]
    d = np.sqrt(_dots(rel, rel))
    d[i] = 1.0
    with np.errstate(invalid="ignore"):  # a coincident agent: 0/0, as the kernel does
        g = rel / d[:, None]
    g[i, 0] = 1.0  # placeholder row for itself (marked invalid)
    gd = _dots(g, relv)
    g_dot = (relv - g * gd[:, None]) / d[:, None]
    noise = rng.standard_normal((n, 8))
    drop = rng.random(n)
    sb, sr, sd, sdd = sig
    gm = g + noise[:, 0:3] * sb
    gm /= np.sqrt(_dots(gm, gm))[:, None]
    gdm = g_dot + noise[:, 3:6] * sr
    dm = d + noise[:, 6] * sd
    ddm = gd + noise[:, 7] * sdd
    valid = (d <= rng_m) & (drop >= dropout)
    valid[i] = False
    return valid, gm, gdm, dm, ddm


class HoldNumpy:
    def __init__(self, n: int, index: int, hold_s: float) -> None:
        self.index, self.hold_s = index, hold_s
        self._last_seen = np.full(n, -np.inf)
        self._last_rp = np.zeros((n, 3))
        self._last_rv = np.zeros((n, 3))

    def pairs(
        self, t: float, valid: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        self._last_seen[valid] = t
        self._last_rp[valid] = rel_p[valid]
        self._last_rv[valid] = rel_v[valid]
        held = ~valid & (t - self._last_seen <= self.hold_s)
        held[self.index] = False
        if not held.any():
            return np.nonzero(valid)[0], rel_p, rel_v
        age = (t - self._last_seen[held])[:, None]
        rp_s, rv_s = rel_p.copy(), rel_v.copy()
        rp_s[held] = self._last_rp[held] + age * self._last_rv[held]
        rv_s[held] = self._last_rv[held]
        return np.nonzero(valid | held)[0], rp_s, rv_s


def _config(rng: np.random.Generator, dropout: float) -> SensingConfig:
    return SensingConfig(
        bearing_noise_rad=float(rng.uniform(0.0, 0.02)),
        bearing_rate_noise_radps=float(rng.uniform(0.0, 0.05)),
        distance_noise_m=float(rng.uniform(0.0, 0.1)),
        range_rate_noise_mps=float(rng.uniform(0.0, 0.1)),
        dropout_prob=dropout,
    )


@pytest.mark.parametrize("dropout", [0.0, 0.3])
def test_compiled_measure_equals_numpy(dropout: float) -> None:
    rng = np.random.default_rng(21)
    for trial in range(300):
        n = int(rng.integers(1, 14))
        i = int(rng.integers(0, n))
        p = rng.normal(0.0, 4.0, (n, 3))
        if n > 2 and trial % 5 == 0:
            p[(i + 1) % n] = p[i]  # a coincident agent: d = 0 (nan bearing), as before
        v = rng.normal(0.0, 2.0, (n, 3))
        cfg = _config(rng, dropout)
        rng_m = float(rng.uniform(1.0, 10.0))
        seed, aid = int(rng.integers(0, 1000)), int(rng.integers(0, 50))
        sensor = Sensor(i, aid, n, cfg, rng_m, seed)
        got = sensor.measure(p, v)
        ref = measure_numpy(p, v, i, np.random.default_rng([seed, aid, 0x5E]),
                            tuple(float(x) for x in sensor.sig), rng_m, dropout)
        assert np.array_equal(got.valid, ref[0]), trial
        _same_in_range(got, ref, p, i, rng_m, trial)
        # the relative state from the measurements, as Measurements computed it in numpy
        assert_close(got.rel_pos(), got.g * got.d[:, None], trial)
        assert_close(got.rel_vel(), got.g_dot * got.d[:, None] + got.g * got.d_dot[:, None],
                     trial)
        # the generator moved by exactly the same draws
        after = np.random.default_rng([seed, aid, 0x5E])
        after.standard_normal((n, 8))
        after.random(n)
        assert sensor.rng.random() == after.random(), trial


def _same_in_range(got, ref: tuple[np.ndarray, ...], p: np.ndarray, i: int, rng_m: float,
                   trial: int) -> int:
    """The kernel's rows in sensing range (and its own) are numpy's; a row out of range
    is invalid and all zeros, its distance included (nothing reads it).
    Returns how many other agents were in range."""
    d = np.sqrt(_dots(p - p[i], p - p[i]))
    near = ~(d > rng_m)
    near[i] = True
    for a, b in zip((got.g, got.g_dot, got.d, got.d_dot), ref[1:], strict=True):
        assert a.shape == b.shape, trial
        assert_close(a[near], b[near], trial)
    far = ~near
    assert not got.valid[far].any(), trial
    for a in (got.g, got.g_dot, got.d, got.d_dot, got.rel_p, got.rel_v):
        assert not a[far].any(), trial
    return int(near.sum()) - 1


def test_compiled_measure_equals_numpy_on_a_swarm() -> None:
    """The kernel gives numpy's measurements (same operations; within rounding,
    tests/reference/close.py: two implementations) and the same validity mask."""
    rng = np.random.default_rng(3)
    p, v = rng.normal(0.0, 3.0, (9, 3)), rng.normal(0.0, 1.0, (9, 3))
    cfg = _config(rng, 0.1)
    got = Sensor(4, 5, 9, cfg, 6.0, 17).measure(p, v)
    sig = (cfg.bearing_noise_rad, cfg.bearing_rate_noise_radps, cfg.distance_noise_m,
           cfg.range_rate_noise_mps)
    ref = measure_numpy(p, v, 4, np.random.default_rng([17, 5, 0x5E]), sig, 6.0, 0.1)
    assert np.array_equal(got.valid, ref[0])
    assert 0 < _same_in_range(got, ref, p, 4, 6.0, 0) < 8  # rows both in and out of range
    # the relative state from the measurements, as Measurements computed it in numpy
    assert_close(got.rel_pos(), got.g * got.d[:, None])
    assert_close(got.rel_vel(), got.g_dot * got.d[:, None] + got.g * got.d_dot[:, None])


def test_compiled_hold_equals_numpy() -> None:
    rng = np.random.default_rng(5)
    for trial in range(40):
        n = int(rng.integers(2, 10))
        index = int(rng.integers(0, n))
        hold_s = float(rng.uniform(0.05, 0.5))
        new, old = DropoutHold(n, index, hold_s, enabled=True), HoldNumpy(n, index, hold_s)
        for k in range(60):
            t = 0.02 * k
            valid = rng.random(n) < 0.6
            valid[index] = False
            rp, rv = rng.normal(0.0, 3.0, (n, 3)), rng.normal(0.0, 1.0, (n, 3))
            sel, rp_s, rv_s = new.pairs(t, valid, rp, rv)
            sel0, rp0, rv0 = old.pairs(t, valid, rp, rv)
            assert sel.dtype == sel0.dtype and np.array_equal(sel, sel0), (trial, k)
            assert np.array_equal(rp_s, rp0) and np.array_equal(rv_s, rv0), (trial, k)
            assert (rp_s is rp) == (rp0 is rp) and (rv_s is rv) == (rv0 is rv), (trial, k)
        assert np.array_equal(new._last_seen, old._last_seen)
        assert np.array_equal(new._last_rp, old._last_rp)
        assert np.array_equal(new._last_rv, old._last_rv)


def test_disabled_hold_passes_valid_pairs_through() -> None:
    hold = DropoutHold(4, 1, 0.2, enabled=False)
    valid = np.array([True, False, False, True])
    rp, rv = np.ones((4, 3)), np.zeros((4, 3))
    sel, rp_s, rv_s = hold.pairs(0.0, valid, rp, rv)
    assert sel.tolist() == [0, 3] and rp_s is rp and rv_s is rv


def test_truth_of_another_shape_is_refused_before_any_draw() -> None:
    """The kernel writes N rows without bounds checks: truth of another shape is a
    ValueError, raised before the noise is drawn (the seeded stream is not advanced)."""
    rng = np.random.default_rng(8)
    cfg = _config(rng, 0.1)
    sensor = Sensor(1, 2, 5, cfg, 6.0, 3)
    ok = rng.normal(0.0, 3.0, (5, 3))
    for p, v in ((rng.normal(size=(6, 3)), ok), (ok, rng.normal(size=(5, 2))),
                 (rng.normal(size=(15,)), ok), (rng.normal(size=(3, 5)), ok)):
        with pytest.raises(ValueError, match="expected"):
            sensor.measure(p, v)
    twin = Sensor(1, 2, 5, cfg, 6.0, 3)
    a = copy.deepcopy(sensor.measure(ok, ok))  # the sensors of a thread share outputs
    b = twin.measure(ok, ok)
    assert np.array_equal(a.rel_p, b.rel_p) and np.array_equal(a.valid, b.valid)


def test_pair_rows_are_the_negated_rows_of_the_selected_pairs() -> None:
    """pair_rows(sel, rel_p, rel_v, dp, dv) writes numpy's -rel_p[sel], -rel_v[sel] bit for
    bit into the first rows of dp, dv (any order, repeats, none; the rest untouched), and
    an index outside the rows or outputs too short are a ValueError."""
    from offboard.estimation.sensing_kernel import pair_rows

    rng = np.random.default_rng(11)
    for _ in range(200):
        n = int(rng.integers(1, 10))
        rel_p, rel_v = rng.normal(0.0, 5.0, (n, 3)), rng.normal(0.0, 2.0, (n, 3))
        sel = rng.integers(0, n, int(rng.integers(0, n + 2))).astype(np.int64)
        m = len(sel)
        dp, dv = np.full((m + 2, 3), 7.0), np.full((m + 2, 3), 7.0)
        pair_rows(sel, rel_p, rel_v, dp, dv)
        assert np.array_equal(dp[:m], -rel_p[sel]) and np.array_equal(dv[:m], -rel_v[sel])
        assert np.all(dp[m:] == 7.0) and np.all(dv[m:] == 7.0)
    out = np.zeros((3, 3))
    for bad in (np.array([3], dtype=np.int64), np.array([-1], dtype=np.int64)):
        with pytest.raises(ValueError, match="outside"):
            pair_rows(bad, np.zeros((3, 3)), np.zeros((3, 3)), out, out)
    with pytest.raises(ValueError, match="fewer rows"):
        pair_rows(np.zeros(4, dtype=np.int64), np.zeros((3, 3)), np.zeros((3, 3)), out, out)


def _in_range(cfg: SensingConfig) -> SensingConfig:
    from dataclasses import replace

    from swarm_common.enums import NoiseDraws

    return replace(cfg, noise_draws=NoiseDraws.IN_RANGE)


def test_in_range_draws_ignore_agents_out_of_range(monkeypatch: pytest.MonkeyPatch) -> None:
    """``noise_draws = "in_range"``: agents out of range change nothing. A swarm and the
    same swarm with 200 more agents far away give the same measurements of every pair in
    range, bit for bit (the same code on the same draws), and the generator advances by
    8 normals and 1 uniform per agent in range only. The draws' room starts at 2 rows
    here, so it grows in most trials, and stays within twice the agents in range."""
    from offboard.estimation import sensing

    monkeypatch.setattr(sensing, "DRAW_ROWS", 2)
    rng = np.random.default_rng(5)
    for trial in range(100):
        # a fresh scratch per trial: the room of this trial's draws
        monkeypatch.setattr(sensing, "_THREAD", threading.local())
        n = int(rng.integers(2, 12))
        i = int(rng.integers(0, n))
        p = rng.normal(0.0, 4.0, (n, 3))
        v = rng.normal(0.0, 2.0, (n, 3))
        cfg = _in_range(_config(rng, 0.3 * float(rng.integers(0, 2))))
        rng_m = float(rng.uniform(1.0, 10.0))
        seed, aid = int(rng.integers(0, 1000)), int(rng.integers(0, 50))
        far = 1e3 + rng.uniform(0.0, 1e3, (200, 3))  # ≥ 1 km away, out of every range
        # the far agents interleaved with the near ones, which keep their order: near
        # agent j sits at row near[j] of the big swarm
        near = np.sort(rng.choice(n + 200, n, replace=False))
        big_p, big_v = np.empty((n + 200, 3)), rng.normal(0.0, 2.0, (n + 200, 3))
        big_p[near], big_v[near] = p, v
        rest = np.setdiff1d(np.arange(n + 200), near)
        big_p[rest] = far
        small = Sensor(i, aid, n, cfg, rng_m, seed)
        big = Sensor(int(near[i]), aid, n + 200, cfg, rng_m, seed)
        for _ in range(3):
            a, b = small.measure(p, v), big.measure(big_p, big_v)
            assert np.array_equal(a.valid, b.valid[near]), trial
            assert not b.valid[rest].any(), trial
            ok = a.valid
            for x, y in ((a.g, b.g), (a.g_dot, b.g_dot), (a.d, b.d), (a.d_dot, b.d_dot),
                         (a.rel_p, b.rel_p), (a.rel_v, b.rel_v)):
                assert np.array_equal(x[ok], y[near][ok]), trial
        in_range = int((np.linalg.norm(p - p[i], axis=1) <= rng_m).sum() - 1)
        # and the draws' room follows the agents in range, not the 200 far ones
        room = sensing.scratch(n + 200, True)
        assert len(room.noise) == len(room.drop) <= max(2, 2 * in_range), trial
        after = np.random.default_rng([seed, aid, 0x5E])
        for _ in range(3):
            after.standard_normal((in_range, 8))
            after.random(in_range)
        assert small.rng.random() == after.random(), trial


def test_in_range_noise_has_the_configured_spread() -> None:
    """The in-range draws are the configured noise: over 4,000 steps the measured distance
    and range rate of a pair in range scatter about the truth with the standard
    deviations of ``[sensing]`` (within 5 %), and no pair is ever dropped at 0 dropout."""
    cfg = _in_range(SensingConfig(bearing_noise_rad=0.01, bearing_rate_noise_radps=0.02,
                                  distance_noise_m=0.05, range_rate_noise_mps=0.1,
                                  dropout_prob=0.0))
    p = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 50.0, 0.0]])
    v = np.array([[0.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    sensor = Sensor(0, 1, 3, cfg, 10.0, 9)
    d, dd = [], []
    for _ in range(4000):
        m = sensor.measure(p, v)
        assert m.valid.tolist() == [False, True, False]
        d.append(m.d[1])
        dd.append(m.d_dot[1])
    assert abs(np.mean(d) - 3.0) < 0.005 and abs(np.mean(dd) + 1.0) < 0.01
    assert np.std(d) == pytest.approx(0.05, rel=0.05)
    assert np.std(dd) == pytest.approx(0.1, rel=0.05)


def test_in_range_outputs_kept_between_calls_equal_fresh_ones() -> None:
    """``noise_draws = "in_range"`` keeps its outputs between calls, shared by the sensors
    of a thread, and rewrites only the rows in range now and those the call before wrote
    (measure_in_range_into). Three sensors of one swarm measure in turn while its agents
    cross the sensing range every few steps: each call's outputs equal, element for
    element, those of measure_into written into new arrays from the same draws (the same
    row code, so bit for bit), rows out of range included: invalid, zeros."""
    from offboard.estimation.sensing_kernel import measure_into

    rng = np.random.default_rng(13)
    seen_in, seen_out = 0, 0
    for trial in range(40):
        n = int(rng.integers(3, 30))
        cfg = _in_range(_config(rng, 0.3 * float(rng.integers(0, 2))))
        sensors, twins = [], []
        for i in rng.choice(n, 3, replace=False).tolist():
            rng_m = float(rng.uniform(2.0, 6.0))
            seed, aid = int(rng.integers(0, 1000)), int(rng.integers(0, 50))
            sensors.append(Sensor(i, aid, n, cfg, rng_m, seed))
            twins.append(np.random.default_rng([seed, aid, 0x5E]))
        p = rng.normal(0.0, 4.0, (n, 3))
        v = rng.normal(0.0, 3.0, (n, 3))
        for step in range(30):
            p = p + 0.3 * v  # agents enter and leave the range
            if step % 7 == 6:
                v = rng.normal(0.0, 3.0, (n, 3))
            for sensor, twin in zip(sensors, twins, strict=True):
                i, rng_m = sensor.index, sensor.range
                got = sensor.measure(p, v)
                d = np.linalg.norm(p - p[i], axis=1)
                near = (d <= rng_m) & (np.arange(n) != i)
                k = int(near.sum())
                # the draws in the rows of the agents in range; zero noise, never dropped,
                # in the others' (out of range or its own: invalid either way)
                noise, drop = np.zeros((n, 8)), np.ones(n)
                noise[near], drop[near] = twin.standard_normal((k, 8)), twin.random(k)
                ref = [np.empty(n, dtype=np.bool_), np.empty((n, 3)), np.empty((n, 3)),
                       np.empty(n), np.empty(n), np.empty((n, 3)), np.empty((n, 3))]
                measure_into(p, v, i, noise, drop, *sensor._sig, rng_m, cfg.dropout_prob,
                             *ref)
                for a, b in zip((got.valid, got.g, got.g_dot, got.d, got.d_dot, got.rel_p,
                                 got.rel_v), ref, strict=True):
                    assert np.array_equal(a, b), (trial, step, i)
                seen_in += k
                seen_out += n - 1 - k
        for sensor, twin in zip(sensors, twins, strict=True):
            assert sensor.rng.random() == twin.random(), trial
    assert seen_in > 0 and seen_out > 0


def test_each_thread_has_its_own_sensor_outputs() -> None:
    """The sensors of two threads never write each other's outputs: a measurement taken in
    another thread keeps its values while this thread's sensors of the same swarm measure,
    and two sensors of one thread return the same arrays (the shared scratch)."""
    rng = np.random.default_rng(21)
    for in_range in (False, True):
        cfg = _config(rng, 0.0)
        cfg = _in_range(cfg) if in_range else cfg
        p, v = rng.normal(0.0, 2.0, (6, 3)), rng.normal(0.0, 1.0, (6, 3))
        got: list[Measurements] = []
        other = Sensor(0, 1, 6, cfg, 5.0, 3)
        t = threading.Thread(target=lambda s=other, x=p, y=v, out=got: out.append(
            s.measure(x, y)))
        t.start()
        t.join()
        kept = copy.deepcopy(got[0])
        a = Sensor(1, 2, 6, cfg, 5.0, 4).measure(p, v)
        b = Sensor(2, 3, 6, cfg, 5.0, 5).measure(p + 1.0, v)
        assert a.rel_p is b.rel_p and got[0].rel_p is not a.rel_p
        for x, y in zip((got[0].valid, got[0].g, got[0].rel_p, got[0].rel_v),
                        (kept.valid, kept.g, kept.rel_p, kept.rel_v), strict=True):
            assert np.array_equal(x, y)
        assert got[0].valid.any()  # the other thread's sensor saw someone
