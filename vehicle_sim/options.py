"""Options of one ``vehicle-sim`` run (the command line, typed) and the vehicle subset."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from swarm_common.enums import DefaultStreams, FailsafeAction
from swarm_common.scenario.model import Scenario


@dataclass
class SimOptions:
    lockstep: bool = False
    seed: int | None = None
    port_offset: int = 0
    bind_host: str = "127.0.0.1"
    remote_host: str = "127.0.0.1"
    swarm: str = "default"
    zenoh: bool = True
    zenoh_mode: str = "peer"
    zenoh_listen: list[str] = field(default_factory=list)
    zenoh_connect: list[str] = field(default_factory=list)
    failsafe: FailsafeAction = FailsafeAction.HOLD
    offboard_timeout: float = 0.5
    odometry_hz: float = 50.0
    step_timeout: float = 0.5
    duration: float | None = None
    vehicles: int | None = None
    stats_out: str | None = None
    params_file: str | None = None  # --params-file: per-vehicle PX4 parameters (JSON)
    signing_key: bytes | None = field(default=None, repr=False)  # never printed
    unsigned_gcs: bool = False  # GCS link: unsigned telemetry requests allowed
    # --default-streams: a link's default remote gets the telemetry always (PX4) or only
    # once a client there has spoken (HEARTBEAT before that; vehicle_sim.link.server_io)
    default_streams: DefaultStreams = DefaultStreams.ALWAYS
    # --home: the geodetic origin (lat °, lon °, alt m AMSL) of the vehicles' local frames;
    # None: PX4 SITL's default (swarm_common.world.geodesy)
    home: tuple[float, float, float] | None = None


def restrict(sc: Scenario, k: int | None) -> Scenario:
    """The scenario with only its first ``k`` agents (``--vehicles K``)."""
    if k is None or k >= sc.n:
        return sc
    if k < 1:
        raise ValueError(f"--vehicles {k}: must be in [1, {sc.n}]")
    return dataclasses.replace(sc, agents=sc.agents[:k])
