"""``gcs mission compare`` when one method's run fails: the others still run, the report
is written with them and names the failed one, the exit status is that failure's (no
process is started here: the distributed run is replaced by a stub)."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gcs.mission import compare_cli, distributed
from gcs.mission.distributed import MissionError
from gcs.mission.launch_spec import LaunchError
from gcs.report import animation, paths, plots
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[3]
CUBE8 = str(ROOT / "scenarios" / "cube8.toml")
METRICS = {"min_distance_m": 1.0, "collisions": 0, "energy_u": 10.0, "energy_thrust": 2000.0,
           "energy_thrust_excess": 5.0, "formation_time_s": None, "qp_fallbacks": 0}


def _stub_run(fail: Mapping[str, Exception], offsets: list[int]) -> Any:
    def run(sc: Any, out: Path, method: str, seed: Any, duration: float, **kw: Any) -> dict:
        offsets.append(kw["port_offset"])
        if method in fail:
            raise fail[method]
        n, k = sc.n, 10
        t = np.arange(k) * 0.1
        p = np.cumsum(np.ones((k, n, 3)) * 0.01, axis=0) + np.arange(n)[None, :, None]
        z = np.zeros_like(p)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(out / "series.npz", t=t, p=p, v=z, p_des=p, z1=p, z2=z, lumped_est=z,
                 lumped_true=z, min_dist=np.full(k, 1.0))
        return {"metrics": dict(METRICS)}
    return run


@pytest.fixture
def no_plots(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("plot_min_distance", "plot_errors", "plot_snapshots", "plot_energy"):
        monkeypatch.setattr(plots, name, lambda *a, **k: None)
    monkeypatch.setattr(paths, "plot_paths", lambda s, *a, **k: paths.closest_of(s, a[3]))
    monkeypatch.setattr(animation, "animate_closest", lambda *a, **k: None)


def _args(out: Path) -> argparse.Namespace:
    return argparse.Namespace(scenario=CUBE8, out=str(out), inproc=False, seed=None,
                              duration=1.0, port_offset=None, processes=None, seeds=0, jobs=1)


@pytest.mark.parametrize(("exc", "code"), [
    (MissionError("the daemon of agent(s) 1 exited before the start: offboard: cannot open "
                  "MAVLink udpin:127.0.0.1:14540: [Errno 98] Address already in use"), 1),
    (LaunchError("udp 14540 (127.0.0.1, agent 1 API port) is in use: offboard-1 could not "
                 "bind it"), 2),
])
def test_one_failed_method_keeps_the_others(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, no_plots: None,
    capsys: pytest.CaptureFixture[str], exc: Exception, code: int,
) -> None:
    offsets: list[int] = []
    monkeypatch.setattr(distributed, "run_and_score", _stub_run({"dcbf": exc}, offsets))
    rc = compare_cli.compare(load_scenario(CUBE8), _args(tmp_path))
    assert rc == code
    assert len(offsets) == 4  # every method was tried, each at a probed offset
    assert all(o % 1000 == 0 for o in offsets)
    text = (tmp_path / "report.md").read_text()
    assert "**Failed runs.** 1 of the 4 methods did not finish" in text
    assert f"(`dcbf`): {str(exc)}" in text
    assert text.count("| Sampled-data CBF (ours) | FAILED: ") == 2
    for label in ("Proposed RCBF", "Improved APF", "No collision avoidance"):
        assert f"| {label} | " in text
    err = capsys.readouterr().err
    assert f"gcs mission compare: dcbf: {str(exc)}" in err


def test_every_method_failed_writes_no_report(monkeypatch: pytest.MonkeyPatch,
                                              tmp_path: Path, no_plots: None) -> None:
    fail = {m: MissionError(f"{m} stalled") for m in compare_cli.METHODS}
    monkeypatch.setattr(distributed, "run_and_score", _stub_run(fail, []))
    assert compare_cli.compare(load_scenario(CUBE8), _args(tmp_path)) == 1
    assert not (tmp_path / "report.md").exists()
