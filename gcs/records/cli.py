"""``gcs log export RUN --format csv|mcap --out DIR [--scenario S]``: argument parsing and
wiring (the hook for ``gcs/cli.py``: :func:`add_log_parser`).

``RUN``: a run folder (``metrics.json`` + ``series.npz``) or a ``record.mcap``.
``--format csv`` writes one ``vehicle_<id>.csv`` per vehicle and ``pairs.csv`` into DIR;
``--format mcap`` converts a run folder (one written before records existed) into
``DIR/record.mcap``. The scenario (agent ids, barrier τ and D, bearings, world) is
``--scenario`` or ``scenarios/<name>.toml`` of the run's scenario name. Bad input (a
missing, truncated or foreign file or folder): one line on stderr, exit 2, nothing written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from gcs.exit_codes import EXIT_USAGE
from swarm_common.inputs import MAX_SCENARIO_BYTES, bounded_file, one_line

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def add_log_parser(subparsers: Any) -> None:
    """Register ``log`` (``log export``) on ``gcs``'s subparsers."""
    p = subparsers.add_parser("log", help="export a run's record (CSV, MCAP)")
    lsub = p.add_subparsers(dest="log_cmd", required=True)
    e = lsub.add_parser("export", help="a run folder or record.mcap as CSV files or MCAP",
                        description="Export a run: one CSV per vehicle + pairs.csv, or "
                        "convert a run folder into record.mcap (docs/records.md).")
    e.add_argument("run", metavar="RUN", help="run folder or record.mcap")
    e.add_argument("--format", choices=("csv", "mcap"), required=True)
    e.add_argument("--out", required=True, metavar="DIR", help="folder to write into")
    e.add_argument("--scenario", default=None,
                   type=bounded_file(MAX_SCENARIO_BYTES, "scenario file"),
                   help="the run's scenario TOML (default scenarios/<name>.toml)")
    e.set_defaults(func=cmd_log_export)


def _fail(msg: str) -> int:
    """One stderr line, exit 2: a NUL or another control character of a path escaped."""
    print(one_line(f"gcs log export: {' '.join(msg.split())}"), file=sys.stderr)
    return EXIT_USAGE


def run_scenario(arg: str | None, name: object, n: int) -> Any:
    """The run's scenario, or None when none is given and none of its name is shipped;
    ``ValueError`` (one line) when the one given cannot be loaded or has another size."""
    from swarm_common.scenario.model import ScenarioError, load_scenario

    path = Path(arg) if arg else SCENARIOS / f"{name}.toml"
    if arg is None and (not isinstance(name, str) or not path.is_file()):
        return None
    try:
        sc = load_scenario(str(path))
    except (ScenarioError, OSError, ValueError) as exc:
        raise ValueError(f"--scenario {path}: {exc}") from None
    if sc.n != n:
        raise ValueError(f"scenario {path} has {sc.n} agents, the run {n}")
    return sc


def cmd_log_export(args: argparse.Namespace) -> int:
    """``gcs log export``; 0 when written, 2 on bad input."""
    from gcs.records.channels import RecordContext
    from gcs.records.export import load_record, load_run_folder, write_csv
    from gcs.records.pair_table import pair_table
    from gcs.records.reader import RecordError
    from gcs.records.writer import write_mcap

    run, out = Path(args.run), Path(args.out)
    if out.exists() and not out.is_dir():
        return _fail(f"--out {out}: exists and is not a folder")
    try:
        if run.is_file() or run.suffix == ".mcap":
            if args.format == "mcap":
                return _fail(f"{run}: is a record already (--format mcap converts a run folder)")
            ids, ser, pairs = load_record(run)
        else:
            doc, ser = load_run_folder(run)
            n = ser.p.shape[1]
            sc = run_scenario(args.scenario, doc.get("scenario"), n)
            if args.format == "mcap":
                c = (RecordContext.from_scenario(sc) if sc is not None
                     else RecordContext.bare(n))
                out.mkdir(parents=True, exist_ok=True)
                print(write_mcap(out / "record.mcap", doc, ser, c))
                return 0
            if sc is None:
                return _fail(f"{run}: scenario {doc.get('scenario')!r} not found: give "
                             "--scenario (the barrier h needs its tau and D)")
            ids = [int(i) for i in sc.ids]
            pairs = pair_table(ser.p, ser.v, sc.controller.tau_safe_s, sc.controller.d_safe_m,
                               sc.controller.dcbf_vertical_scale)
    except (RecordError, ValueError) as exc:
        return _fail(str(exc))
    try:
        files = write_csv(out, ids, ser, pairs)
    except OSError as exc:
        return _fail(f"--out {out}: {exc.strerror or exc}")
    print(f"wrote {len(files)} files into {out}")
    return 0
