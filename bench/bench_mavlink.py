"""MAVLink messages per second one simulated vehicle endpoint handles (no asserts).

    .venv/bin/python bench/bench_mavlink.py [--seconds 3] [--rates 2000 5000 10000 20000 0]

Starts ``vehicle-sim --vehicles 1 --no-zenoh`` on a free port offset, arms vehicle 1,
then a sender blasts a 50/50 mix of SET_ATTITUDE_TARGET and COMMAND_LONG
(REQUEST_MESSAGE of an unsupported id, so every one is parsed, dispatched and ACKed)
at vehicle 1's API port, at each target rate (0 = as fast as the sender can). The
simulator's own counters (printed at SIGTERM) give how many were processed.
Also measures the in-process cost: parse + dispatch per message, without sockets.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sys
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as M

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from conftest import SimProcess, free_port_offset  # noqa: E402

from swarm_common.ports import vehicle_ports  # noqa: E402


def frames(n: int) -> list[bytes]:
    enc = M.MAVLink(None, srcSystem=255, srcComponent=190)
    out = []
    for k in range(n):
        if k % 2 == 0:
            m = M.MAVLink_set_attitude_target_message(k, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.34)
        else:
            m = M.MAVLink_command_long_message(1, 1, 512, 0, 99999, 0, 0, 0, 0, 0, 0)
        out.append(m.pack(enc))
        enc.seq = (enc.seq + 1) % 256
    return out


def stats_of(sim: SimProcess) -> dict[str, int]:
    line = [ln for ln in sim.lines if "stats:" in ln][-1]
    return {k: int(v) for k, v in (kv.split("=") for kv in line.split("stats: ")[1].split())}


def run_rate(rate: float, seconds: float) -> tuple[int, int, float, dict[str, int]]:
    off = free_port_offset(1)
    sim = SimProcess(
        ["--scenario", str(ROOT / "scenarios/cube8.toml"), "--port-offset", str(off),
         "--vehicles", "1", "--no-zenoh", "--quiet"], off,
    )  # fmt: skip
    try:
        time.sleep(1.5)
        dest = ("127.0.0.1", vehicle_ports(1, off).api_local)
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.setblocking(False)
        fr = frames(512)
        sent = 0
        t0 = time.perf_counter()
        end = t0 + seconds
        while True:
            now = time.perf_counter()
            if now >= end:
                break
            if rate > 0 and sent >= (now - t0) * rate:
                time.sleep(0.0005)
                continue
            try:
                s.sendto(fr[sent % len(fr)], dest)
                sent += 1
            except BlockingIOError:
                pass
            if sent % 256 == 0:  # drain the ACKs so our socket buffer never matters
                try:
                    while True:
                        s.recv(65535)
                except BlockingIOError:
                    pass
        el = time.perf_counter() - t0
        time.sleep(1.0)
        s.close()
    finally:
        sim.proc.send_signal(signal.SIGTERM)
        sim.proc.wait(10)
        sim._reader.join(2)
    st = stats_of(sim)
    return sent, st["setpoints"] + st["commands"], el, st


def inprocess(n: int = 20000) -> float:
    from swarm_common.scenario.model import load_scenario
    from vehicle_sim.physics.dynamics import SwarmDynamics
    from vehicle_sim.vehicle import Vehicle

    sc = load_scenario(ROOT / "scenarios/cube8.toml")
    dyn = SwarmDynamics(sc, held=True)
    v = Vehicle(1, 0, dyn)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.robust_parsing = True
    fr = frames(512)
    t0 = time.perf_counter()
    for k in range(n):
        for m in mav.parse_buffer(fr[k % len(fr)]) or []:
            v.handle(m, ("api", ("127.0.0.1", 1)), 0.0, 0.0)
        if len(v.outbox) > 64:
            for msg, _ in v.outbox:
                v.pack(msg)
            v.outbox.clear()
    return n / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--rates", type=float, nargs="+", default=[2000, 5000, 10000, 20000, 0])
    a = ap.parse_args()
    os.environ.setdefault("MAVLINK20", "1")
    print(f"in-process parse + dispatch (+ ACK packing): {inprocess():,.0f} msgs/s")
    print(f"{'target/s':>9} {'sent/s':>9} {'processed/s':>12} {'processed %':>12}")
    for r in a.rates:
        sent, done, el, st = run_rate(r, a.seconds)
        print(f"{'max' if r == 0 else f'{r:.0f}':>9} {sent / el:9,.0f} {done / el:12,.0f} "
              f"{100.0 * done / max(sent, 1):11.1f}%")  # fmt: skip


if __name__ == "__main__":
    main()
