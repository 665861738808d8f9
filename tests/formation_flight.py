"""A distributed lockstep run of course8 with the formation vehicle served, flown by a
ground-station client thread: shared by the formation-vehicle tests (mission upload,
MAVSDK, flying live)."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
from conftest import ROOT, free_port_offset

from gcs.formation.vehicle import FORMATION_PORT
from gcs.mission.distributed import run_distributed
from gcs.mission.launch_spec import SigningChoice
from swarm_common.scenario.model import Scenario, dump_toml, load_scenario, with_overrides
from swarm_common.signing import generate_key

WAIT_AT = (2.0, 2.0, 4.0)  # ENU (m): course8 forms where it starts and waits there


def waiting_course8(tmp_path: Path) -> Scenario:
    """course8 with a one-waypoint mission at :data:`WAIT_AT` (hold 1 s), loaded from a file
    as every process of the run loads it."""
    base = load_scenario(ROOT / "scenarios" / "course8.toml")
    sc = with_overrides(base, mission={"speed_mps": 1.5, "waypoint": [
        {"centroid": list(WAIT_AT), "hold_s": 1.0}]})
    path = tmp_path / "wait8.toml"
    path.write_text(dump_toml(sc.to_toml_dict()))
    return load_scenario(path)


def swarm_key(tmp_path: Path) -> Path:
    """A fresh signing key for the run and its ground station."""
    key_path = tmp_path / "keys" / "swarm.key"
    generate_key(key_path)
    return key_path


def formation_port() -> tuple[int, int]:
    """(a free port offset, the formation vehicle's UDP port at it)."""
    off = free_port_offset()
    return off, FORMATION_PORT + off


def fly_with(client: threading.Thread, sc: Scenario, tmp_path: Path, off: int,
             duration: float, key_path: Path | None,
             join_s: float = 5.0) -> tuple[Any, dict[str, Any]]:
    """Start ``client``, run ``sc`` distributed (dcbf, two daemon processes, signed with
    ``key_path`` or unsigned without one) with the formation vehicle on its port, then join
    the client and close its ``conn`` if it has one; returns (recorder, run facts)."""
    signing = SigningChoice(key=key_path) if key_path else SigningChoice(enabled=False)
    client.start()
    try:
        return run_distributed(
            sc, tmp_path / "run", "dcbf", None, duration, port_offset=off,
            show_progress=False, signing=signing, processes=2,
            formation_port=FORMATION_PORT + off,
        )
    finally:
        client.join(join_s)
        conn = getattr(client, "conn", None)
        if conn is not None:
            conn.close()


def assert_passes(centroid: Any, waypoints: list[tuple[float, float, float]],
                  within_m: float = 0.5) -> None:
    """The centroid (K, 3) comes within ``within_m`` of each waypoint, in order."""
    k = 0
    for wp in waypoints:
        d = np.linalg.norm(centroid[k:] - np.array(wp), axis=1)
        hit = np.flatnonzero(d <= within_m)
        assert hit.size, (f"the centroid never came within {within_m:g} m of {wp} "
                          f"(closest {d.min():.2f})")
        k += int(hit[0])
