"""The dcbf follower's step up to the QP in one compiled call (offboard.safety.dcbf.front,
the product's only dcbf path) against the same step composed part by part from Python
(the follower's path of the other methods, ending in DcbfFilter.apply): whole in-process
missions agree, over the families whose steps take each branch (every pair sensed,
dropouts held, predicted pairs, the solver called, the ground barrier, take-off and
landing references)."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from typing import Any

import numpy as np
import pytest
from conftest import ROOT, load_shipped

import offboard.safety.dcbf.front as front_mod
from gcs.mission.inproc import MissionResult, run_inproc
from offboard.agent.follower import FollowerAgent
from offboard.safety.base import saturate_norm
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.kernel import saturate_into

# Both paths call the same kernels with the same arguments in the same order, so here
# they give the same bits; the comparison allows a relative 1e-9 (about 4.5e6 ulp at
# 1.0) so that a platform whose Python-side additions or copies round differently in the
# last bit (e.g. another numpy build) is not mistaken for a different filter: a real
# difference in the rows or the QP moves the trajectories by far more within seconds.
RTOL, ATOL = 1e-9, 1e-12


def _run(name: str, duration: float, composed: bool, monkeypatch: pytest.MonkeyPatch,
         calls: Counter[str], land_at: float | None = None) -> MissionResult:
    """``name`` run in process with dcbf; ``composed``: every dcbf step part by part
    (the reference) instead of the compiled call. ``calls`` counts each path's steps and
    the compiled calls with predicted rows."""
    sc = load_shipped(ROOT / "scenarios" / f"{name}.toml")
    run, composed_step = front_mod.DcbfFront.run, FollowerAgent._composed_step

    def counted_run(self: front_mod.DcbfFront, *a: Any, **kw: Any) -> Any:
        calls["front"] += 1
        unsensed = kw.get("unsensed", a[5] if len(a) > 5 else front_mod.NO_UNSENSED)
        calls["front_predicted"] += int(len(unsensed.idx) > 0)
        return run(self, *a, **kw)

    def counted_composed(self: FollowerAgent, *a: Any) -> Any:
        calls["composed"] += 1
        return composed_step(self, *a)

    def reference_step(self: FollowerAgent, *a: Any) -> Any:
        return self._composed_step(*a[:-1])  # not the odometry: it has no world rows

    with monkeypatch.context() as mp:
        mp.setattr(front_mod.DcbfFront, "run", counted_run)
        mp.setattr(FollowerAgent, "_composed_step", counted_composed)
        if composed:
            mp.setattr(FollowerAgent, "_filter_step", reference_step)
        return run_inproc(sc, "dcbf", duration=duration, land_at=land_at)


def _assert_same_run(a: MissionResult, b: MissionResult) -> None:
    for f in dataclasses.fields(a.series):
        if f.name == "solve_us":  # wall-clock
            continue
        x, y = np.asarray(getattr(a.series, f.name)), np.asarray(getattr(b.series, f.name))
        if x.dtype.kind == "f":
            np.testing.assert_allclose(x, y, rtol=RTOL, atol=ATOL, err_msg=f.name)
        else:
            assert np.array_equal(x, y), f.name
    assert a.collision_pairs == b.collision_pairs
    skip = ("wall", "real_time", "factor", "solve")
    ma = {k: v for k, v in a.metrics.items() if not any(s in k for s in skip)}
    mb = {k: v for k, v in b.metrics.items() if not any(s in k for s in skip)}
    assert ma.keys() == mb.keys()
    for k, v in ma.items():
        if isinstance(v, float):
            assert math.isclose(v, mb[k], rel_tol=RTOL, abs_tol=ATOL) or v == mb[k], k
        else:
            assert repr(v) == repr(mb[k]), k


@pytest.mark.full
@pytest.mark.parametrize(
    ("name", "duration", "land_at"),
    [("cube8", 4.0, None), ("cube8_noise5", 4.0, None), ("grid12", 3.0, None),
     ("ground8", 9.0, 6.0)],
)
def test_missions_in_one_call_equal_part_by_part(
    name: str, duration: float, land_at: float | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    fused_calls: Counter[str] = Counter()
    parts_calls: Counter[str] = Counter()
    fused = _run(name, duration, False, monkeypatch, fused_calls, land_at)
    parts = _run(name, duration, True, monkeypatch, parts_calls, land_at)
    _assert_same_run(fused, parts)
    assert fused_calls["front"] > 0 and fused_calls["composed"] == 0  # one path only ...
    assert parts_calls["front"] == 0  # ... and the reference never took it
    assert parts_calls["composed"] == fused_calls["front"]


@pytest.mark.full
def test_predicted_pairs_and_solver_steps_are_covered(monkeypatch: pytest.MonkeyPatch) -> None:
    """The families above reach the branches the equality is meant for: with dropouts
    some compiled calls carry predicted rows, and in the crossing grid the QP solver
    runs after the compiled shortcut failed."""
    calls: Counter[str] = Counter()
    _run("cube8_noise5", 4.0, False, monkeypatch, calls)
    assert calls["front_predicted"] > 0
    solve_rows = DcbfFilter.solve_rows

    def counted(self: DcbfFilter, *a: Any, **kw: Any) -> Any:
        calls["unheld" if kw.get("unheld") else "held-check"] += 1
        return solve_rows(self, *a, **kw)

    monkeypatch.setattr(DcbfFilter, "solve_rows", counted)
    _run("grid12", 3.0, False, monkeypatch, calls)
    assert calls["unheld"] > 0  # the solver after the compiled shortcut failed


def test_saturate_into_is_saturate_norm() -> None:
    """The compiled saturation gives saturate_norm's answer, at the bound, beyond it,
    below it, and for non-finite input: within 2 ulp (the same three products, sum,
    square root and scaling, each correctly rounded in IEEE arithmetic; the tolerance only
    allows for a platform that contracts or reorders one of them)."""
    rng = np.random.default_rng(11)
    xs = [rng.standard_normal(3) * 10.0 ** rng.uniform(-6, 6) for _ in range(4000)]
    xs += [np.array([2.0, 0.0, 0.0]), np.array([0.0, 0.0, -2.0]),
           np.array([math.nan, 1.0, 0.0]), np.array([math.inf, 0.0, 0.0]), np.zeros(3)]
    out = np.empty(3)
    for x in xs:
        for bound in (2.0, 0.5, 1e-3):
            saturate_into(x, bound, out)
            with np.errstate(invalid="ignore"):  # inf · 0 is nan in both
                want = saturate_norm(x, bound)
            want = np.asarray(want, dtype=np.float64)
            finite = np.isfinite(want)
            assert np.array_equal(np.isnan(out), np.isnan(want))
            assert np.array_equal(out[~finite & ~np.isnan(want)], want[~finite & ~np.isnan(want)])
            np.testing.assert_array_max_ulp(out[finite], want[finite], maxulp=2)
