"""The formation vehicle in a distributed run: served from the runner's step hook."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from gcs.formation.vehicle import FormationVehicle
from gcs.mission.recorder import Recorder
from swarm_common import wire
from swarm_common.scenario.spec import Scenario
from swarm_common.signing import load_key


def formation_hook(
    sc: Scenario, rec: Recorder, session: Any, swarm: str, port: int,
    key_path: Path | None,
) -> tuple[Callable[[int], None], FormationVehicle]:
    """(the runner's on_step callback, the vehicle): each step the vehicle takes the latest
    truth the recorder holds and publishes its commands on ``session``. Raises OSError
    when its port is busy, MissionError when the scenario has no mission."""

    def publish(cmd: wire.Command) -> None:
        session.put(wire.key_cmd(swarm, cmd.kind), wire.encode(cmd))

    key = load_key(key_path) if key_path is not None else None
    fv = FormationVehicle(sc, publish, port, key=key)

    def on_step(k: int) -> None:
        with rec.lock:
            row = min(max(k, 0), rec.steps)
            have = bool(rec.have_truth[row])
            p = rec.p[row].astype(float) if have else None
            v = rec.v[row].astype(float) if have else None
        fv.serve(row * sc.control_dt, p, v)

    return on_step, fv
