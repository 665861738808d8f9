"""The distributed runner's step hooks (``on_step(k)``, called while the run goes): the
land-all sender, and the formation vehicle (:mod:`gcs.formation`) served from the recorder's
truth."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from gcs.formation.vehicle import FormationVehicle
from gcs.mission.recorder import Recorder
from swarm_common import wire
from swarm_common.enums import CommandKind
from swarm_common.scenario.spec import Scenario
from swarm_common.signing import load_key


def formation_hook(
    sc: Scenario, rec: Recorder, session: Any, swarm: str, port: int,
    key_path: Path | None,
) -> tuple[Callable[[int], None], FormationVehicle]:
    """(the runner's on_step callback, the vehicle): each step the vehicle takes the latest
    truth the recorder holds and publishes its commands on ``session``. The vehicle stays
    silent (the truth withheld) until every leader's daemon has reported a status: truth
    flows before the daemons step, and a command put before they take commands is lost.
    Raises OSError when its port is busy, MissionError when the scenario has no mission."""

    def publish(cmd: wire.Command) -> None:
        session.put(wire.key_cmd(swarm, cmd.kind), wire.encode(cmd))

    key = load_key(key_path) if key_path is not None else None
    fv = FormationVehicle(sc, publish, port, key=key)

    leaders = [sc.index_of(i) for i in sc.leader_ids]
    flying = [False]  # every leader's daemon has stepped (a status of a step >= 1)

    def on_step(k: int) -> None:
        with rec.lock:
            row = min(max(k, 0), rec.steps)
            if not flying[0] and row >= 1:
                flying[0] = bool(rec.have_status[1:row + 1][:, leaders].any(axis=0).all())
            have = flying[0] and bool(rec.have_truth[row])
            p = rec.p[row].astype(float) if have else None
            v = rec.v[row].astype(float) if have else None
        fv.serve(row * sc.control_dt, p, v)

    return on_step, fv


def each(hooks: list[Callable[[int], None]]) -> Callable[[int], None] | None:
    """One on_step callback that calls every one of ``hooks`` in order (None: none)."""
    if not hooks:
        return None

    def call(k: int) -> None:
        for hook in hooks:
            hook(k)

    return call


def land_sender(session: Any, swarm: str, land_at: float, dt: float) -> Callable[[int], None]:
    """on_step callback: (re)publish the land command every 0.5 s (wall) from step 1 on
    (every agent subscribed) until the run is 1 s past ``land_at``; the daemons keep the
    first one they receive."""
    key = wire.key_cmd(swarm, CommandKind.LAND)
    payload = wire.encode(wire.Command(kind=CommandKind.LAND, at_s=float(land_at)))
    last = [0.0]

    def send(k: int) -> None:
        now = time.monotonic()
        if k >= 1 and k * dt <= land_at + 1.0 and now - last[0] >= 0.5:
            session.put(key, payload)
            last[0] = now

    return send
