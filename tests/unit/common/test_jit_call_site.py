"""Kernel call sites (swarm_common.jit.CallSite): after its first call a site calls the
compiled entry point directly, with the results of the kernel; in checked mode
(``$SWARM_JIT_CHECK=1``) a changed argument type is refused, and the flight paths that
use sites keep their types from step to step."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit, typeof

from gcs.mission.inproc import run_inproc
from offboard.safety.dcbf.kernel import saturate_into
from swarm_common.jit import CHECK_ENV, CallSite
from swarm_common.scenario.model import load_scenario


def test_a_site_gives_the_kernels_results(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(CHECK_ENV, raising=False)
    rng = np.random.default_rng(4)
    site = CallSite(saturate_into)
    assert site.types is None
    for trial in range(50):
        x = rng.normal(0.0, 3.0, 3)
        bound = float(rng.uniform(0.1, 5.0))
        got, want = np.empty(3), np.empty(3)
        site.call(x, bound, got)
        saturate_into(x, bound, want)
        assert np.array_equal(got, want), trial  # the same compiled code, one process
        assert np.linalg.norm(got) <= bound * (1.0 + 1e-12)
    assert site.types == (typeof(x), typeof(bound), typeof(got))


def test_checked_site_refuses_a_changed_type(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(CHECK_ENV, "1")
    site = CallSite(saturate_into)
    out = np.zeros(3)
    site.call(np.array([3.0, 4.0, 0.0]), 1.0, out)
    assert np.allclose(out, [0.6, 0.8, 0.0], rtol=0, atol=1e-15)
    out[:] = 7.0
    with pytest.raises(TypeError, match="saturate_into.*types changed"):
        site.call(np.array([3.0, 4.0, 0.0], dtype=np.float32), 1.0, out)
    assert np.all(out == 7.0)  # refused before the kernel ran
    with pytest.raises(TypeError, match="saturate_into"):
        site.call(np.array([3.0, 9.0, 4.0, 9.0, 0.0, 9.0])[::2], 1.0, out)  # strided (3,)


@pytest.mark.parametrize("name,seconds", [
    ("cube8", 2.0),            # every agent sensed, a few QPs
    ("cube8_obstacles", 2.0),  # world rows
    ("grid27_knn", 1.0),       # in-range sensing, the transient speed rows, unsensed rows
    ("cube8_rogue", 1.0),      # a non-cooperative vehicle
])
def test_flight_paths_keep_their_types(monkeypatch: pytest.MonkeyPatch, name: str,
                                       seconds: float) -> None:
    """Every site of a run, checked on every call, keeps its first call's types, and the
    checked run flies the same bits as the unchecked one."""
    sc = load_scenario(f"scenarios/{name}.toml")
    monkeypatch.setenv(CHECK_ENV, "1")
    checked = run_inproc(sc, "dcbf", duration=seconds)
    monkeypatch.delenv(CHECK_ENV)
    plain = run_inproc(sc, "dcbf", duration=seconds)
    for series in ("p", "v", "u", "z1", "h_min"):
        assert np.array_equal(getattr(checked.series, series), getattr(plain.series, series),
                              equal_nan=True), series


def test_a_site_whose_first_call_was_converted_stays_with_the_dispatcher(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A first call the dispatcher served by converting an argument to a compiled
    signature (an int where only a float64 one exists, compiling disabled) leaves the site
    on the dispatcher, which then types every call: no entry point is taken for types it
    was not compiled for."""
    monkeypatch.delenv(CHECK_ENV, raising=False)
    scaled = njit(lambda x, b: x[0] * b)
    scaled.compile("float64(float64[::1], float64)")
    scaled.disable_compile()
    site = CallSite(scaled)
    assert site.call(np.array([3.0]), 2) == 6.0  # 2 converted to 2.0
    assert site.types is None and site.call is scaled
    assert site.call(np.array([1.5]), 3) == 4.5
