"""``gcs`` command line: ``gcs mission run|compare SCENARIO``, ``gcs router``, ``gcs dashboard``.

``mission run`` and ``mission compare`` are distributed (real processes, lockstep) unless
``--inproc``; the seed sweep of ``compare --seeds N`` always runs in process.

Subcommands are registered in :data:`COMMANDS` as ``name -> add_parser(subparsers)``;
each ``add_parser`` sets ``func`` on its parser (``func(args) -> int``). To add a command
(e.g. ``router``, ``dashboard``) append ``COMMANDS["router"] = add_router_parser``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

METHODS = ("rcbf", "apf", "none")
# ``runner(args, scenario) -> exit code`` for ``mission run`` without ``--inproc``
# (gcs.mission.cli_run); None = not available.
DISTRIBUTED_RUNNER: Callable[[argparse.Namespace, object], int] | None = None


def _distributed_runner() -> Callable[[argparse.Namespace, object], int] | None:
    if DISTRIBUTED_RUNNER is not None:
        return DISTRIBUTED_RUNNER
    try:
        from gcs.mission import cli_run
    except ImportError:
        return None
    return cli_run


def _load(path: str):
    from swarm_common.scenario import ScenarioError, load_scenario

    try:
        return load_scenario(path)
    except ScenarioError as exc:
        print(f"gcs: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


def _json_default(x):
    from gcs.mission import _json_default as jd

    return jd(x)


def cmd_mission_run(args: argparse.Namespace) -> int:
    sc = _load(args.scenario)
    if not args.inproc:
        runner = _distributed_runner()
        if runner is None:
            print("gcs mission run: distributed runs: not yet available (use --inproc)",
                  file=sys.stderr)
            return 2
        return runner(args, sc)
    from gcs.inproc import run_inproc

    res = run_inproc(sc, args.method, seed=args.seed, duration=args.duration, progress=True)
    if args.out:
        res.save(args.out)
        print(f"wrote {args.out}/metrics.json, series.npz", file=sys.stderr)
    doc = {"scenario": sc.name, "method": res.method, "seed": res.seed, "metrics": res.metrics}
    if args.json:
        print(json.dumps(doc, default=_json_default))
    else:
        for k, v in res.metrics.items():
            print(f"{k:24s} {v}")
    return 0


def _run_one(job: tuple[str, str, int, float | None]) -> dict:
    from gcs.inproc import run_inproc
    from swarm_common.scenario import load_scenario

    path, method, seed, duration = job
    return run_inproc(load_scenario(path), method, seed=seed, duration=duration).metrics


def _gain_lines(sc) -> list[str]:
    from offboard.agent import FollowerAgent, make_agent

    ag = make_agent(sc, sc.follower_ids[0])
    return ag.gains.lines() if isinstance(ag, FollowerAgent) else []


def cmd_router(args: argparse.Namespace) -> int:
    from gcs.router import run_router

    return run_router(args.listen)


def add_router_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("router", help="run a Zenoh router (multi-machine setups)")
    p.add_argument("--listen", nargs="+", default=["tcp/127.0.0.1:7447"], metavar="EP",
                   help="endpoints to listen on (default tcp/127.0.0.1:7447)")
    p.set_defaults(func=cmd_router)


def add_dashboard(sub: argparse._SubParsersAction) -> None:
    from gcs.dashboard.cli import add_dashboard_parser

    add_dashboard_parser(sub)


def cmd_mission_compare(args: argparse.Namespace) -> int:
    sc = _load(args.scenario)
    from gcs.inproc import run_inproc
    from gcs.report import compare_table, seeds_table, write_report
    from offboard.bearing import formation_from_scenario

    out = Path(args.out or "runs/compare")
    metrics: dict[str, dict] = {}
    series: dict[str, dict] = {}
    gains: list[str] = []
    for m in METHODS:
        if args.inproc:
            print(f"running {m} in process ...", file=sys.stderr)
            res = run_inproc(sc, m, seed=args.seed, duration=args.duration, progress=False)
            res.save(out / m)
            metrics[m] = res.metrics
            series[m] = res.series.as_dict()
            gains = res.gains
            continue
        from gcs.mission import MissionError, run_and_score

        duration = float(sc.run.duration_s if args.duration is None
                         else args.duration)
        print(f"running {m}: vehicle-sim + {sc.n} offboard daemons, lockstep ...",
              file=sys.stderr)
        try:
            doc = run_and_score(sc, out / m, m, args.seed, duration,
                                port_offset=args.port_offset, show_progress=True)
        except KeyboardInterrupt:
            print("\ngcs mission compare: interrupted; every process stopped", file=sys.stderr)
            return 130
        except MissionError as exc:
            print(f"\ngcs mission compare: {exc}", file=sys.stderr)
            return 1
        metrics[m] = doc["metrics"]
        import numpy as np

        with np.load(out / m / "series.npz") as z:
            series[m] = {k: z[k] for k in z.files}
        if not gains:
            gains = _gain_lines(sc)
    seeds = None
    if args.seeds and args.seeds > 1:
        from concurrent.futures import ProcessPoolExecutor

        base = sc.seed if args.seed is None else args.seed
        jobs = [(args.scenario, m, base + s, args.duration) for m in METHODS
                for s in range(args.seeds)]
        print(f"seed sweep: {len(jobs)} runs ...", file=sys.stderr)
        with ProcessPoolExecutor(max_workers=args.jobs) as ex:
            res_all = list(ex.map(_run_one, jobs))
        seeds = {m: [r for (_, mm, _, _), r in zip(jobs, res_all, strict=True) if mm == m]
                 for m in METHODS}
    form = formation_from_scenario(sc)
    d_safe = sc.controller.d_safe_m
    path = write_report(out, sc.name, metrics, series, form.follower_idx, form.edges, d_safe,
                        gains, seeds,
                        mode="in-process" if args.inproc else
                        "distributed (vehicle-sim + one offboard process per agent, lockstep)")
    print(compare_table(metrics, d_safe))
    if seeds:
        print(seeds_table(seeds, d_safe))
    print(f"wrote {path}", file=sys.stderr)
    return 0


def _seconds(text: str, allow_zero: bool) -> float:
    import math

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise argparse.ArgumentTypeError(
            f"{text!r}: must be a finite number of seconds {'>= 0' if allow_zero else '> 0'}"
        )
    return v


def _positive_seconds(text: str) -> float:
    return _seconds(text, allow_zero=False)


def _non_negative_seconds(text: str) -> float:
    return _seconds(text, allow_zero=True)


def add_mission_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("mission", help="run or compare missions")
    msub = p.add_subparsers(dest="mission_cmd", required=True)
    r = msub.add_parser("run", help="run one mission")
    r.add_argument("scenario")
    r.add_argument("--inproc", action="store_true", help="all in one process (no MAVLink)")
    r.add_argument("--method", choices=METHODS, default=None)
    r.add_argument("--seed", type=int, default=None)
    r.add_argument("--duration", type=_positive_seconds, default=None,
                   help="seconds (default: scenario)")
    r.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    r.add_argument("--out", default=None, help="directory for metrics.json + series.npz")
    d = r.add_argument_group("distributed runs (without --inproc)")
    d.add_argument("--realtime", action="store_true", help="wall-clock ticks, not lockstep")
    d.add_argument("--port-offset", type=int, default=0, help="added to every UDP/TCP port")
    d.add_argument("--kill-agent", type=int, default=None, help="kill this agent's process ...")
    d.add_argument("--kill-at", type=_non_negative_seconds, default=None,
                   help="... at this mission time (s)")
    r.set_defaults(func=cmd_mission_run)
    c = msub.add_parser("compare", help="run rcbf, apf and none and write a report")
    c.add_argument("scenario")
    c.add_argument("--inproc", action="store_true")
    c.add_argument("--seed", type=int, default=None)
    c.add_argument("--duration", type=_positive_seconds, default=None)
    c.add_argument("--seeds", type=int, default=0, help="also sweep N seeds per method")
    c.add_argument("--jobs", type=int, default=2, help="parallel processes for the sweep")
    c.add_argument("--out", default=None, help="report directory (default runs/compare)")
    c.add_argument("--port-offset", type=int, default=0, help="distributed: shift every port")
    c.set_defaults(func=cmd_mission_compare)


COMMANDS: dict[str, Callable[[argparse._SubParsersAction], None]] = {
    "mission": add_mission_parser,
    "router": add_router_parser,
    "dashboard": add_dashboard,
}


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="gcs", description="bearing-swarm ground station")
    sub = ap.add_subparsers(dest="command", required=True)
    for add in COMMANDS.values():
        add(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
