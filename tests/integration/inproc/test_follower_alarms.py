"""A follower's in-flight alarms and fallback in process (offboard.agent.guard,
docs/safety.md "In-flight alarms and the fallback"): cube8 with 0.5 m/s range-rate noise
loses its estimates, raises RESIDUAL and falls back instead of flying away; plain cube8
raises nothing and flies exactly as without the guard."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CUBE8

import offboard.agent.guard as guard
from gcs.mission.inproc import run_inproc
from offboard.safety.monitor import monitor_config
from swarm_common.enums import AgentAlarm
from swarm_common.scenario.model import load_scenario, with_overrides


def _no_guard(monkeypatch: pytest.MonkeyPatch) -> None:
    """The guard switched off: no bits, never a fallback."""
    monkeypatch.setattr(guard.InFlightGuard, "check",
                        lambda self, *a: AgentAlarm(0))


def test_plain_cube8_raises_nothing_and_flies_as_without_the_guard(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sc = load_scenario(CUBE8)
    # 25 s: the crossing, the 5 s outage and the formation (the rest is steady tracking)
    with_guard = run_inproc(sc, "dcbf", seed=3, duration=25.0)
    assert not np.any(with_guard.series.alarms)
    _no_guard(monkeypatch)
    without = run_inproc(sc, "dcbf", seed=3, duration=25.0)
    # the guard only reads: every recorded series and metric bit for bit the same (but the
    # wall-clock QP times)
    for k, v in without.series.as_dict().items():
        if k != "solve_us":
            np.testing.assert_array_equal(getattr(with_guard.series, k), v, err_msg=k)
    for k, v in without.metrics.items():
        if any(w in k for w in ("solve", "_us", "wall", "realtime", "cpu")):  # clock
            continue
        assert with_guard.metrics[k] == v or (v != v and with_guard.metrics[k] != v), k


def test_noisy_cube8_alarms_and_falls_back(monkeypatch: pytest.MonkeyPatch) -> None:
    sc = with_overrides(load_scenario(CUBE8, allow_unsafe=True),
                        sensing={"range_rate_noise_mps": 0.5})
    res = run_inproc(sc, "dcbf", seed=1, duration=60.0)
    s = res.series
    a = s.alarms.astype(int)
    err = np.linalg.norm(s.z1 - s.p, axis=2)
    assert np.any(a & AgentAlarm.RESIDUAL) and np.any(a & AgentAlarm.FALLBACK)
    # the residual fired within 1 s of the first estimate leaving the bound (2.77 m)
    cross = int(np.argmax(np.any(err > monitor_config(sc).bound_m, axis=1)))
    k_res = int(np.argmax(np.any(a & AgentAlarm.RESIDUAL, axis=1)))
    assert cross > 0 and 0.0 < (k_res - cross) * sc.control_dt <= 1.0
    fell = np.nonzero(np.any(a & AgentAlarm.FALLBACK, axis=0))[0]
    for i in fell:
        k_fb = int(np.argmax(a[:, i] & AgentAlarm.FALLBACK))
        assert np.all(a[k_fb:, i] & AgentAlarm.FALLBACK)  # latched
        # it stays near where it fell back (held, then landed): bounded, on its odometry
        d = np.linalg.norm(s.p[k_fb:, i, :2] - s.p[k_fb, i, :2], axis=1)
        assert d.max() < 15.0, (i, d.max())  # horizontally; then straight down
        assert np.max(s.p[k_fb:, i, 2]) < s.p[k_fb, i, 2] + 15.0
        assert s.p[-1, i, 2] < 0.2  # landed by the end (hold 3 s, then 0.6 m/s down)
    # without the guard the same run loses its swarm: estimates and vehicles far away
    _no_guard(monkeypatch)
    lost = run_inproc(sc, "dcbf", seed=1, duration=30.0).series
    reach = np.linalg.norm(s.p[: len(lost.t)], axis=2).max()
    assert np.linalg.norm(lost.p, axis=2).max() > 2.0 * reach
