"""Distributed cube8: lockstep × real time, CPU and RSS per process; real-time latency.

    .venv/bin/python bench/bench_distributed.py [--duration 20] [--port-offset 900]
        [--processes N] [--default-streams always|on-contact] [--scenario FILE] [--skip-realtime]
        [--method rcbf|dcbf|apf|none]

The method defaults to rcbf, the one every earlier round's figures were measured with.

Prints (no assertions): the lockstep stepping rate (sim seconds per wall second, start-up
excluded), CPU seconds, CPU ms per step and peak RSS of every process, over the whole run
and over the stepping alone (CPU from the first step on, start-up excluded) (with
``--processes N`` the daemons packed into N processes: also per agent, and RSS / agents),
the daemons' mean CPU ms per agent-step, and for a real-time run the
setpoint-to-odometry latency distribution and the fraction of late cycles (> one
control period) measured by vehicle-sim.
"""

from __future__ import annotations

import argparse
import json
import re
import tempfile
from pathlib import Path

from gcs.mission.distributed import run_and_score
from offboard.daemon.packing import parse_agents
from swarm_common.enums import DefaultStreams, Method
from swarm_common.scenario.model import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "cube8.toml"))
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--port-offset", type=int, default=900)
    ap.add_argument("--skip-realtime", action="store_true")
    ap.add_argument("--default-streams", choices=[d.value for d in DefaultStreams],
                    default=DefaultStreams.ALWAYS.value,
                    help="the simulator's default telemetry (gcs mission run --default-streams)")
    ap.add_argument("--processes", type=int, default=None,
                    help="pack the daemons into N processes (default: one per agent)")
    ap.add_argument("--method", choices=[m.value for m in Method], default=Method.RCBF.value,
                    help="safety filter of the run (default rcbf, as the earlier figures)")
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    with tempfile.TemporaryDirectory() as tmp:
        doc = run_and_score(sc, Path(tmp) / "lockstep", args.method, None, args.duration,
                            port_offset=args.port_offset, show_progress=False,
                            processes=args.processes,
                            default_streams=DefaultStreams(args.default_streams))
        run = doc["run"]
        layout = ("one process per agent" if args.processes is None
                  else f"{args.processes} daemon processes")
        layout += f", default streams {args.default_streams}, {args.method}"
        print(f"lockstep {sc.name} {args.duration:.0f} s, {layout}: stepping "
              f"{run['stepping_realtime_factor']:.2f}x real time "
              f"(whole run incl. start-up {args.duration / run['wall_s']:.2f}x)")
        print("whole run (start-up included):")
        print_processes(run["processes"], args.duration * sc.run.control_hz)
        first = run.get("processes_at_first_step")
        if first:
            print(f"stepping only (CPU from the first step to the end, "
                  f"{run['steps_from_first']} steps; start-up excluded):")
            stepping = stepping_usage(run["processes"], first)
            print_processes(stepping, run["steps_from_first"])
            print_outside_control(stepping, Path(tmp) / "lockstep")
        m = doc["metrics"]
        print(f"min_distance_m {m['min_distance_m']:.3f}  collisions {m['collisions']}")
        if not args.skip_realtime:
            doc = run_and_score(sc, Path(tmp) / "realtime", args.method, None, args.duration,
                                realtime=True, port_offset=args.port_offset + 50,
                                show_progress=False)
            lat = doc["run"].get("simulator", {}).get("latency", {})
            print("real-time setpoint-to-odometry latency:", json.dumps(lat))
            m = doc["metrics"]
            print(f"real-time min_distance_m {m['min_distance_m']:.3f}  "
                  f"collisions {m['collisions']}")


def stepping_usage(
    end: dict[str, dict[str, float]], first: dict[str, dict[str, float]]
) -> dict[str, dict[str, float]]:
    """Each process's CPU spent after the first step (peak RSS as at the end)."""
    return {name: {"cpu_s": u["cpu_s"] - first[name]["cpu_s"], "peak_rss_mib": u["peak_rss_mib"]}
            for name, u in end.items() if name in first}


CONTROL_LINE = re.compile(r"agent (\d+): stopped;.*control CPU ([0-9.]+) s over (\d+) steps")


def print_outside_control(stepping: dict[str, dict[str, float]], run_dir: Path) -> None:
    """Daemon CPU per agent-step outside the control law: stepping CPU of the daemon
    processes minus the CPU their agents spent in ``agent.step`` (each daemon's last log
    line), over the control steps they ran."""
    control, steps = 0.0, 0
    for log_path in sorted(run_dir.glob("offboard-*.log")):
        for m in CONTROL_LINE.finditer(log_path.read_text(errors="replace")):
            control, steps = control + float(m.group(2)), steps + int(m.group(3))
    total = sum(u["cpu_s"] for name, u in stepping.items() if name.startswith("offboard-"))
    if steps == 0:
        print("daemon control CPU: no 'control CPU' lines in the daemons' logs")
        return
    print(f"daemons, stepping: {1000 * total / steps:.2f} ms CPU per agent-step, of which "
          f"control {1000 * control / steps:.2f} ms and outside control "
          f"{1000 * (total - control) / steps:.2f} ms ({steps} agent-steps)")


def print_processes(procs: dict[str, dict[str, float]], steps: float) -> None:
    """CPU and RSS per process; per agent for the daemons (packed or not)."""
    print(f"{'process':24s} {'agents':>6s} {'cpu_s':>7s} {'ms/step':>8s} {'ms/agent-step':>14s} "
          f"{'peak RSS MiB':>13s} {'MiB/agent':>10s}")
    daemon_cpu, agents = 0.0, 0
    for name, u in procs.items():
        n = len(parse_agents(name.removeprefix("offboard-"))) if name.startswith("offboard-") else 0
        per = 1000 * u["cpu_s"] / steps
        print(f"{name:24s} {n:6d} {u['cpu_s']:7.2f} {per:8.2f} "
              f"{per / n if n else float('nan'):14.2f} {u['peak_rss_mib']:13.1f} "
              f"{u['peak_rss_mib'] / n if n else float('nan'):10.1f}")
        if n:
            daemon_cpu, agents = daemon_cpu + u["cpu_s"], agents + n
    if agents:
        print(f"daemons: {1000 * daemon_cpu / steps / agents:.2f} ms CPU per agent-step")


if __name__ == "__main__":
    main()
