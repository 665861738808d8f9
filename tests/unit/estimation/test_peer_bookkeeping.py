"""A follower's bookkeeping of the other agents' estimates, against plain references:
``NeighbourAccel`` (two slots per agent, the older overwritten) against a list of every
accepted estimate, ``NeighbourPredictor.predict_rows`` against ``get_at`` per agent and
its table against a dict of the last accepted estimates (given as estimates or as an
in-process batch), over random streams with late, duplicate, out-of-order, stale and
unknown-agent estimates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.estimation.neighbour_accel import NeighbourAccel
from offboard.estimation.peer_table import EstimateBatch
from offboard.estimation.predictor import NeighbourPredictor
from offboard.records import NeighbourEstimate

IDS = [3, 5, 8, 13, 21]
A_MAX = 6.0


def _estimate(rng: np.random.Generator, aid: int, t: float) -> NeighbourEstimate:
    return NeighbourEstimate(aid, t, rng.normal(size=3), rng.normal(0.0, 3.0, 3),
                             rng.normal(size=3), rng.normal(size=12), bool(aid == 3),
                             bool(rng.random() < 0.8))


def _reference_accel(history: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """The last two accepted estimates' velocity difference, norm-bounded by A_MAX."""
    if len(history) < 2:
        return np.zeros(3)
    (t0, z0), (t1, z1) = history[-2], history[-1]
    a = (z1 - z0) / (t1 - t0)
    n = math.sqrt(float(a @ a))
    return a * (A_MAX / n) if n > A_MAX else a


def test_neighbour_accel_keeps_the_last_two_newer_estimates() -> None:
    rng = np.random.default_rng(3)
    acc = NeighbourAccel(IDS, A_MAX)
    history: dict[int, list[tuple[float, np.ndarray]]] = {aid: [] for aid in IDS}
    for k in range(600):
        batch = {}
        for aid in [*IDS, 99]:  # 99 is not in the scenario: ignored
            if rng.random() < 0.6:
                # mostly the next period, sometimes a repeat or an older one
                t = 0.02 * (k + int(rng.choice([0, 0, 0, -1, -3])))
                batch[aid] = _estimate(rng, aid, t)
        acc.ingest(batch)
        for aid, e in batch.items():
            h = history.get(aid)
            if h is not None and (not h or e.t > h[-1][0] + 1e-9):
                h.append((e.t, e.z2.copy()))
        idx = rng.permutation(len(IDS))[: int(rng.integers(0, len(IDS) + 1))]
        got = acc.rows(idx)
        want = np.array([_reference_accel(history[IDS[j]]) for j in idx]).reshape(-1, 3)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12)


def test_predict_rows_is_get_of_each_agent() -> None:
    rng = np.random.default_rng(4)
    pred = NeighbourPredictor(IDS, 0.4, 0.02, (4.0, 3.0), (2.0, 2.5), max_age=0.5, a_max=10.0)
    stale = 0
    for k in range(300):
        t = 0.02 * k
        batch = {aid: _estimate(rng, aid, t + 0.02 * float(rng.choice([1, 1, 0, -2, -10])))
                 for aid in IDS if rng.random() < 0.5}
        pred.ingest(batch, comm_ok=bool(rng.random() < 0.9))
        ask = rng.permutation(len(IDS))[: int(rng.integers(1, len(IDS) + 1))]
        rows, have = pred.predict_rows(ask.astype(np.int64), t)
        stale += rows is not pred.table.rows
        for j in ask.tolist():
            want = pred.get_at(j, t)
            assert bool(have[j]) == (want is not None)
            if want is not None:
                for cols, w in zip((slice(0, 3), slice(3, 6), slice(9, 21)), want, strict=True):
                    assert np.array_equal(rows[j, cols], w)
    assert stale > 0  # aged data was predicted, not only read


def test_table_keeps_the_newest_estimate_per_agent() -> None:
    """The predictor's table against a dict of the last accepted estimate per agent (one at
    least as new as the last, only while the link is up), its revision (first heard, or a
    changed cooperative flag: it moves exactly when who is heard or who cooperates
    changed) and the same estimates handed over as an in-process batch."""
    rng = np.random.default_rng(5)
    pred = NeighbourPredictor(IDS, 0.4, 0.02, (4.0, 3.0), (2.0, 2.5))
    twin = NeighbourPredictor(IDS, 0.4, 0.02, (4.0, 3.0), (2.0, 2.5))
    last: dict[int, NeighbourEstimate] = {}
    for k in range(400):
        before = pred.revision
        batch = {aid: _estimate(rng, aid, 0.02 * (k + int(rng.choice([0, 0, -1, -4]))))
                 for aid in [*IDS, 99] if rng.random() < 0.6}
        up = bool(rng.random() < 0.85)
        pred.ingest(batch, comm_ok=up)
        b, idx = EstimateBatch.from_estimates(twin.index_of, len(IDS), batch)
        twin.ingest_batch(b, np.arange(len(IDS), dtype=np.int64), up)
        changed = False
        for aid, e in batch.items() if up else ():
            old = last.get(aid)
            if aid in IDS and (old is None or e.t >= old.t):
                changed |= old is None or old.cooperative != e.cooperative
                last[aid] = e
        assert (pred.revision != before) == changed and pred.revision == twin.revision
        assert pred.newest == twin.newest == max((e.t for e in last.values()), default=-math.inf)
        for j, aid in enumerate(IDS):
            e = last.get(aid)
            for tab in (pred.table, twin.table):
                assert tab.t[j] == (-math.inf if e is None else e.t)
                if e is not None:
                    assert np.array_equal(tab.rows[j], np.concatenate([e.z1, e.z2, e.z3, e.xi]))
                    assert tab.leader[j] == e.is_leader and tab.cooperative[j] == e.cooperative
        assert np.array_equal(pred.table.acc_t, twin.table.acc_t, equal_nan=True)


def test_unsensed_candidates_pass_over_only_what_is_certainly_out_of_range() -> None:
    """unsensed_candidates keeps, in the order heard, every heard agent but the own one
    and the sensed ones, except current rows farther than the range (with its margin)
    from z1: never a stale row, never a row the exact norm puts within range."""
    from offboard.agent.unsensed import RANGE_MARGIN
    from offboard.estimation.peer_table import ROW, unsensed_candidates

    rng = np.random.default_rng(6)
    passed_over = 0
    for _ in range(300):
        n = int(rng.integers(1, 12))
        rows = rng.normal(0.0, 4.0, (n, ROW))
        t_tab = rng.choice([1.0, 1.0 - 1e-12, 0.98, -math.inf], n)
        z1 = rng.normal(0.0, 4.0, 3)
        r = float(rng.uniform(0.5, 9.0))
        heard = np.sort(rng.permutation(n)[: int(rng.integers(0, n + 1))]).astype(np.int64)
        sensed = rng.permutation(n)[: int(rng.integers(0, n + 1))].astype(np.int64)
        own = int(rng.integers(0, n))
        got = unsensed_candidates(heard, own, sensed, t_tab, rows, z1, np.zeros(3), 1.0, 1e-9,
                                  (r * (1 + RANGE_MARGIN)) ** 2, np.zeros(0), r, 0.0,
                                  RANGE_MARGIN).tolist()
        others = [j for j in heard.tolist() if j != own and j not in set(sensed.tolist())]
        assert got == [j for j in others if j in got]  # a subsequence, in the order heard
        for j in others:
            d = z1 - rows[j, 0:3]
            exact = math.sqrt(float(d.dot(d)))
            current = 1.0 - t_tab[j] <= 1e-9
            if j not in got:
                assert current and exact > r
                passed_over += 1
            elif current:
                assert exact <= r * (1 + 2 * RANGE_MARGIN)
    assert passed_over > 0


def test_with_the_reach_only_pairs_certainly_beyond_range_and_reach_are_passed_over() -> None:
    """With the load check's reach, unsensed_candidates passes over a current row only
    where the exact test of offboard.agent.unsensed (BLAS norms, the Python pair_reach)
    would: beyond the sensing range and beyond the reach at the closing speed. Random
    tables with distances and closing speeds around both, and rows near each edge."""
    from offboard.agent.unsensed import RANGE_MARGIN
    from offboard.estimation.peer_table import ROW, reach_bound, unsensed_candidates
    from swarm_common.scenario.transient_check import pair_reach

    rng = np.random.default_rng(44)
    passed_over = kept_beyond_range = 0
    for _ in range(400):
        n = int(rng.integers(2, 16))
        terms = (float(rng.uniform(0.0, 1.5)), float(rng.uniform(0.2, 1.0)),
                 float(rng.choice([0.0, rng.uniform(0.5, 8.0)])), float(rng.uniform(0.0, 0.3)))
        r = float(rng.uniform(1.0, 8.0))
        dv_step = float(rng.uniform(0.0, 0.5))
        rows = rng.normal(0.0, 1.0, (n, ROW))
        z1, z2 = rng.normal(0.0, 3.0, 3), rng.normal(0.0, 1.0, 3)
        for j in range(n):  # distances around the range and the reach, closing speeds 0-6
            u = rng.normal(size=3)
            w = rng.normal(size=3)
            v = float(rng.uniform(0.0, 6.0))
            rows[j, 3:6] = z2 - v * w / np.linalg.norm(w)
            edge = pair_reach(v + dv_step, *terms) if rng.random() < 0.5 else r
            dist = edge * (1.0 + float(rng.choice([-1e-3, -1e-7, 0.0, 1e-7, 1e-3, 0.5])))
            rows[j, 0:3] = z1 - dist * u / np.linalg.norm(u)
        t_tab = rng.choice([1.0, 0.9], n)
        heard = np.arange(n, dtype=np.int64)
        got = set(unsensed_candidates(heard, 0, np.zeros(0, np.int64), t_tab, rows, z1, z2,
                                      1.0, 1e-9, math.inf, np.array(terms), r, dv_step,
                                      RANGE_MARGIN).tolist())
        for j in range(1, n):
            dp, dv = z1 - rows[j, 0:3], z2 - rows[j, 3:6]
            dist = math.sqrt(float(dp.dot(dp)))
            beyond = dist > r and dist > pair_reach(math.sqrt(float(dv.dot(dv))) + dv_step,
                                                    *terms)
            if j not in got:
                assert t_tab[j] == 1.0 and beyond, (j, dist, r)
                passed_over += 1
            elif t_tab[j] == 1.0 and beyond:
                kept_beyond_range += 1  # within the margin: left to the exact test
    assert passed_over > 100 and kept_beyond_range > 0
    for v in (0.0, 0.3, 2.0, 7.5):  # the compiled twin is the formula (a few ulps apart)
        for terms in ((0.8, 0.5, 5.0, 0.17), (0.0, 0.4, 2.0, 0.0), (1.2, 0.7, 0.0, 0.1)):
            assert reach_bound(v, *terms) == pytest.approx(pair_reach(v, *terms), rel=1e-14)


def test_an_index_outside_the_table_is_refused_with_nothing_written() -> None:
    import pytest

    from offboard.estimation.peer_table import PeerTable, unsensed_candidates

    tab = PeerTable(3)
    b = EstimateBatch.empty(3)
    b.t[:] = 1.0
    for bad in (np.array([0, 3]), np.array([-1])):
        with pytest.raises(ValueError, match="outside"):
            tab.ingest(b, bad, True)
        for heard, sensed in ((bad, np.zeros(0, np.int64)), (np.zeros(0, np.int64), bad)):
            with pytest.raises(ValueError, match="outside"):
                unsensed_candidates(heard, 0, sensed, tab.t, tab.rows, np.zeros(3),
                                    np.zeros(3), 1.0, 1e-9, 1.0, np.zeros(0), 1.0, 0.0, 1e-6)
    assert np.all(tab.t == -math.inf) and np.all(np.isnan(tab.acc_t))
    pred = NeighbourPredictor([1, 2, 3], 0.4, 0.02, (4.0, 3.0), (2.0, 2.5))
    with pytest.raises(ValueError, match="outside"):
        pred.predict_rows(np.array([5], dtype=np.int64), 0.0)


def test_full_share_rows_equal_the_numpy_mask() -> None:
    """full_share_rows equals ``full[sel] | (others_heard & (t[sel] < since))`` on random
    tables (never-heard stamps included), and refuses an index outside the table."""
    import pytest

    from offboard.estimation.peer_table import full_share_rows

    rng = np.random.default_rng(12)
    for _ in range(300):
        n = int(rng.integers(1, 12))
        full = rng.random(n) < 0.3
        t_tab = rng.choice([1.0, 0.9, 0.5, -math.inf], n)
        sel = rng.integers(0, n, int(rng.integers(0, n + 1))).astype(np.int64)
        since, heard = float(rng.choice([0.8, 0.95, 1.1])), bool(rng.random() < 0.7)
        want = full[sel] | (heard & (t_tab[sel] < since))
        got = ~want  # every row must be written
        full_share_rows(sel, full, t_tab, since, heard, got)
        assert np.array_equal(got, want)
    with pytest.raises(ValueError, match="outside"):
        full_share_rows(np.array([4], np.int64), np.zeros(4, bool), np.zeros(4), 0.0, True,
                        np.zeros(1, bool))
    with pytest.raises(ValueError, match="length"):
        full_share_rows(np.array([0], np.int64), np.zeros(4, bool), np.zeros(4), 0.0, True,
                        np.zeros(2, bool))
