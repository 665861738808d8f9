"""The dcbf follower's step up to the QP in one compiled call (offboard.safety.dcbf.front) against
the same step part by part (``FollowerAgent.fused = False``): whole in-process missions
give the same bits, over the families whose steps take each branch (every pair sensed,
dropouts held, predicted pairs, the solver called, the ground barrier, take-off and
landing references)."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import offboard.safety.dcbf.front as front_mod
from gcs.mission.inproc import MissionResult, run_inproc
from offboard.agent.follower import FollowerAgent
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.front import saturate_into
from offboard.safety.filter import saturate_norm
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[2]


def _run(name: str, duration: float, fused: bool, monkeypatch: pytest.MonkeyPatch,
         calls: Counter[str], land_at: float | None = None) -> MissionResult:
    sc = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    run, composed = front_mod.DcbfFront.run, FollowerAgent._composed_step

    def counted_run(self: front_mod.DcbfFront, *a: Any) -> Any:
        calls["front"] += 1
        return run(self, *a)

    def counted_composed(self: FollowerAgent, *a: Any) -> Any:
        calls["composed"] += 1
        return composed(self, *a)

    with monkeypatch.context() as mp:
        mp.setattr(FollowerAgent, "fused", fused)
        mp.setattr(front_mod.DcbfFront, "run", counted_run)
        mp.setattr(FollowerAgent, "_composed_step", counted_composed)
        return run_inproc(sc, "dcbf", duration=duration, land_at=land_at)


def _assert_same_bits(a: MissionResult, b: MissionResult) -> None:
    for f in dataclasses.fields(a.series):
        if f.name == "solve_us":  # wall-clock
            continue
        x, y = getattr(a.series, f.name), getattr(b.series, f.name)
        assert np.asarray(x).tobytes() == np.asarray(y).tobytes(), f.name
    assert a.collision_pairs == b.collision_pairs
    skip = ("wall", "real_time", "factor", "solve")
    ma = {k: v for k, v in a.metrics.items() if not any(s in k for s in skip)}
    mb = {k: v for k, v in b.metrics.items() if not any(s in k for s in skip)}
    assert repr(ma) == repr(mb)


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
    fused = _run(name, duration, True, monkeypatch, fused_calls, land_at)
    parts = _run(name, duration, False, monkeypatch, parts_calls, land_at)
    _assert_same_bits(fused, parts)
    assert fused_calls["front"] > 0  # the fused run took the compiled path ...
    assert parts_calls["front"] == 0  # ... and the other never did
    assert parts_calls["composed"] == fused_calls["front"] + fused_calls["composed"]


def test_predicted_pairs_and_solver_steps_are_covered(monkeypatch: pytest.MonkeyPatch) -> None:
    """The families above reach the branches the equality is meant for: with dropouts
    some steps have a predicted pair (the part-by-part path inside a fused run), and
    in the crossing grid the QP solver runs after the compiled shortcut failed."""
    calls: Counter[str] = Counter()
    _run("cube8_noise5", 4.0, True, monkeypatch, calls)
    assert calls["composed"] > 0
    solve_rows = DcbfFilter.solve_rows

    def counted(self: DcbfFilter, *a: Any, **kw: Any) -> Any:
        calls["unheld" if kw.get("unheld") else "held-check"] += 1
        return solve_rows(self, *a, **kw)

    monkeypatch.setattr(DcbfFilter, "solve_rows", counted)
    _run("grid12", 3.0, True, monkeypatch, calls)
    assert calls["unheld"] > 0  # the solver after the compiled shortcut failed


def test_saturate_into_is_saturate_norm() -> None:
    """The compiled saturation gives saturate_norm's bits, at the bound, beyond it, below
    it, and for non-finite input."""
    rng = np.random.default_rng(11)
    xs = [rng.standard_normal(3) * 10.0 ** rng.uniform(-6, 6) for _ in range(20000)]
    xs += [np.array([2.0, 0.0, 0.0]), np.array([0.0, 0.0, -2.0]),
           np.array([math.nan, 1.0, 0.0]), np.array([math.inf, 0.0, 0.0]), np.zeros(3)]
    out = np.empty(3)
    for x in xs:
        for bound in (2.0, 0.5, 1e-3):
            saturate_into(x, bound, out)
            with np.errstate(invalid="ignore"):  # inf · 0 is nan in both
                want = saturate_norm(x, bound)
            assert out.tobytes() == np.asarray(want, dtype=np.float64).tobytes()
