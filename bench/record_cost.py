"""What the MCAP record (gcs.records, issue 43) adds to a cube8 in-process run.

    python bench/record_cost.py [--duration 60] [--repeats 5] [--scenario scenarios/cube8.toml]

Times, alternately (A B A B ..., so a drift of the shared machine's speed hits both), the
whole command ``gcs mission run SCENARIO --inproc --out DIR`` in a fresh process (start-up,
imports, the run and its files: what a user waits for) without the record (A) and with
``write_record`` called on its results in the same process (B: the foxglove-sdk import
included; B also reads the series and the scenario back, which ``write_run`` has in
memory). Prints the median wall time of each, the median of the pairwise ratios B / A, the
median time of ``write_record`` alone (its import included, the reading back not) and
what it adds to A, and the record's size. No assertions.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_RUN = """
import json, sys, time
from pathlib import Path
from gcs.cli import main
out = Path(sys.argv[1])
rc = main(["--log-level", "error", "mission", "run", sys.argv[2], "--inproc", "--out",
           str(out), "--duration", sys.argv[3]])
if sys.argv[4] == "record":
    import numpy as np
    from gcs.records.series import RunSeries
    from swarm_common.scenario.model import load_scenario
    with np.load(out / "series.npz") as z:  # in write_run the series is in memory
        ser = RunSeries(**{k: z[k] for k in z.files})
    doc, sc = json.loads((out / "metrics.json").read_text()), load_scenario(sys.argv[2])
    t0 = time.perf_counter()
    from gcs.records.writer import write_record
    write_record(out, doc, ser, sc)
    print(f"WRITE {time.perf_counter() - t0:.6f}", file=sys.stderr)
"""


def one(scenario: str, duration: float, record: bool) -> tuple[float, float | None, int]:
    """(wall s of the whole process, write_record s or None, record bytes or 0)."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run"
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-c", _RUN, str(out), scenario, str(duration),
                            "record" if record else "plain"], cwd=ROOT, capture_output=True,
                           text=True, check=False)
        wall = time.perf_counter() - t0
        if p.returncode not in (0, 3):
            sys.exit(f"run failed ({p.returncode}): {p.stderr.strip()[-400:]}")
        w = [float(x.split()[1]) for x in p.stderr.splitlines() if x.startswith("WRITE ")]
        rec = out / "record.mcap"
        return wall, (w[0] if w else None), (rec.stat().st_size if rec.exists() else 0)


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    plain, rec, ratio, write, size = [], [], [], [], 0
    for _ in range(a.repeats):
        wa, _w, size_a = one(a.scenario, a.duration, False)
        wb, wr, size = one(a.scenario, a.duration, True)
        if size_a:
            print("note: the plain run wrote record.mcap already (write_run records): A "
                  "includes the record; read the write_record time")
        plain.append(wa)
        rec.append(wb)
        ratio.append(wb / wa)
        if wr is not None:
            write.append(wr)
        print(f"  without {wa:.3f} s  with {wb:.3f} s  write_record {wr:.3f} s", flush=True)
    med = statistics.median
    print(f"{Path(a.scenario).stem}, {a.duration:g} s in process, {a.repeats} pairs:")
    print(f"  command without the record: median {med(plain):.3f} s")
    print(f"  command with the record:    median {med(rec):.3f} s")
    print(f"  ratio with / without:       median {med(ratio):.3f} "
          f"(+{100 * (med(ratio) - 1):.1f} %)")
    if write:
        print(f"  write_record alone:         median {med(write):.3f} s "
              f"(+{100 * med(write) / med(plain):.1f} % of the command without)")
    print(f"  record size:                {size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
