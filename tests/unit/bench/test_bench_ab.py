"""bench/bench_ab.py: the figure it reads from each benchmark's output, and its ratios.

The samples are lines the three stepping benchmarks print (their f-strings, filled in);
a benchmark that changes its wording breaks this test before it breaks a comparison."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]


def _load():
    spec = importlib.util.spec_from_file_location("bench_ab", ROOT / "bench" / "bench_ab.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_ab"] = mod
    spec.loader.exec_module(mod)
    return mod


AB = _load()


@pytest.mark.parametrize(("line", "want"), [
    ("lockstep cube8 20 s, one process per agent, default streams always, dcbf: stepping "
     "3.37x real time (whole run incl. start-up 2.44x)", 3.37),
    ("in-process cube8 60 s [dcbf]: wall 1.47 s, 40.9x real time", 40.9),
    ("  -> cube8 [dcbf]: 40.9-43.4x real time", 43.4),
])
def test_default_figure_reads_the_stepping_rate(line: str, want: float) -> None:
    got = re.compile(AB.DEFAULT_FIGURE).findall(line)
    assert float(got[-1]) == want


def test_the_whole_run_rate_is_not_the_stepping_rate() -> None:
    # bench_distributed prints the stepping rate first: the last match would be the
    # whole-run figure in parentheses, which has no "real time" after it
    line = "stepping 3.37x real time (whole run incl. start-up 2.44x)"
    assert re.compile(AB.DEFAULT_FIGURE).findall(line) == ["3.37"]


def test_paired_ratios_pair_round_by_round() -> None:
    assert AB.paired_ratios([2.0, 4.0], [3.0, 2.0]) == [1.5, 0.5]
    with pytest.raises(ValueError):
        AB.paired_ratios([1.0], [1.0, 2.0])


def test_a_missing_command_is_a_usage_error() -> None:
    with pytest.raises(SystemExit) as exc:
        AB.main(["--rounds", "2"])
    assert exc.value.code == 2


def test_runs_started_together_each_give_their_figure(tmp_path: Path) -> None:
    """--together's two runs: both started before either is read, each read whole."""
    for name, rate in (("a", 2.5), ("b", 7.25)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "bench.py").write_text(
            f"import sys\nprint('warming', file=sys.stderr)\nprint('stepping {rate}x real time')\n")
    figure = re.compile(AB.DEFAULT_FIGURE)
    procs = {n: AB.start_run(tmp_path / n, ["bench.py"]) for n in ("a", "b")}
    got = {n: AB.finish_run(p, tmp_path / n, ["bench.py"], figure, 60.0)
           for n, p in procs.items()}
    assert got == {"a": 2.5, "b": 7.25}


def test_a_run_without_its_figure_stops_the_comparison(tmp_path: Path) -> None:
    (tmp_path / "bench.py").write_text("print('no figure here')\n")
    proc = AB.start_run(tmp_path, ["bench.py"])
    with pytest.raises(SystemExit, match="figure not found"):
        AB.finish_run(proc, tmp_path, ["bench.py"], re.compile(AB.DEFAULT_FIGURE), 60.0)
