"""A fixed, recorded swarm state: deterministic snapshots, docs screenshots, demos.

``recorded_view(scenario)`` is the cube8 swarm 20 s into a formation: leaders placed,
followers near their vertices, vehicle 6 silent for 7.3 s (red), vehicle 8's offboard
daemon missing on Zenoh, one QP fallback, a few bad packets.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from swarm_common.enums import Method, QPStatus
from swarm_common.scenario.model import Scenario, load_scenario

from .state import (
    DashEvent,
    RecordedSource,
    SwarmView,
    VehicleRow,
    as_vec3,
    cube_edges,
    desired_from_leaders,
    failsafe_label,
    nearest_neighbours,
)

DEFAULT_SCENARIO = Path(__file__).resolve().parents[3] / "scenarios" / "cube8.toml"

# fixed offsets from the desired vertex (ENU m), per id
OFFSETS = {
    1: (0.02, -0.01, 0.00),
    2: (-0.01, 0.03, 0.01),
    3: (0.12, 0.08, -0.05),
    4: (-0.06, 0.15, 0.10),
    5: (0.20, -0.10, 0.04),
    6: (-0.45, 0.30, -0.20),
    7: (0.05, -0.07, 0.02),
    8: (0.30, 0.25, -0.12),
}


NOTICE = mavlink.MAV_SEVERITY_NOTICE
WARNING = mavlink.MAV_SEVERITY_WARNING
ERROR = mavlink.MAV_SEVERITY_ERROR
CRIT = mavlink.MAV_SEVERITY_CRITICAL


def recorded_history(n: int = 80, d_safe: float = 0.5) -> list[float]:
    """Minimum distance at 4 Hz: a close pass near D_safe while forming, then the cube."""
    out = []
    for k in range(n):
        t = k / 4.0
        base = 3.6 - 2.7 * math.exp(-t / 6.0)
        dip = math.exp(-((t - 15.5) ** 2) / 1.5) * (base - 0.9 * d_safe)
        out.append(round(base - dip, 3))
    return out


def recorded_view(sc: Scenario | None = None) -> tuple[SwarmView, list[DashEvent]]:
    sc = sc or load_scenario(DEFAULT_SCENARIO)
    ids = sc.ids
    verts = sc.vertices()
    lead = {i: np.asarray(sc.agents[sc.index_of(i)].position, float) for i in sc.leader_ids}
    t = 20.0
    for k, i in enumerate(sc.leader_ids):  # the leaders have moved along their path
        lead[i] = lead[i] + np.array([0.6, 0.3, 0.15]) * (1 - 0.2 * k)
    cube = desired_from_leaders(ids, verts, sc.leader_ids, lead)
    pos = {i: cube[i] + np.array(OFFSETS.get(i, (0.0, 0.0, 0.0))) for i in ids}
    nn, dmin = nearest_neighbours(pos)
    rows = []
    for k, i in enumerate(ids):
        a = sc.agents[k]
        p = pos[i]
        r = VehicleRow(
            id=i,
            role=a.role,
            mode="OFFBOARD",
            armed=True,
            hb_age=0.1 + 0.1 * (k % 3),
            rate_hz=48.0 + (k % 4),
            link_lost=False,
            pos=(float(p[0]), float(p[1]), float(p[2])),
            vel=(0.12 * (k % 3), -0.05 * (k % 2), 0.02 * k - 0.06),
            p_des=as_vec3(cube[i]),
            track_err=float(np.linalg.norm(p - cube[i])),
            est_err=0.02 + 0.015 * k,
            nn_dist=nn[i],
            h_min=round(nn[i] - sc.controller.d_safe_m, 3),
            qp_status=QPStatus.SOLVED,
            qp_us=60.0 + 7 * k,
            method=Method.RCBF,
            status_missing=False,
            status_age=0.02,
        )
        est = "ok"
        if i == 6:
            r.mode, r.hb_age, r.rate_hz, r.link_lost = "OFFBOARD", 7.3, 0.0, True
        if i == 8:
            r.status_missing, r.h_min, r.qp_status, r.qp_us, r.method = True, None, None, None, None
            r.est_err = None
        if i == 5:
            r.qp_status = QPStatus.FALLBACK
        r.failsafe = failsafe_label(r, True, est, False)
        rows.append(r)
    view = SwarmView(
        t=t,
        rows=rows,
        desired={i: as_vec3(cube[i]) for i in ids},
        cube_edges=cube_edges(ids, verts),
        d_safe=float(sc.controller.d_safe_m),
        min_dist=dmin,
        min_dist_history=recorded_history(d_safe=float(sc.controller.d_safe_m)),
        bad_packets=3,
        bad_payloads=1,
        link="udp 127.0.0.1:14550",
        zenoh="missing 1",
        swarm="cube8",
        method=Method.RCBF,
        sim_time=t,
    )
    events = [
        DashEvent(0.4, 0, "cmd", "arm -> ALL", NOTICE),
        DashEvent(0.5, 1, "armed", "armed", NOTICE),
        DashEvent(0.5, 2, "armed", "armed", NOTICE),
        DashEvent(2.1, 0, "cmd", "start formation (OFFBOARD) -> ALL", NOTICE),
        DashEvent(2.2, 3, "mode", "mode POSCTL -> OFFBOARD", NOTICE),
        DashEvent(8.9, 5, "fallback", "QP fallback (infeasible), total 1", WARNING),
        DashEvent(12.0, 0, "outage", "outage 2 s (all) published", NOTICE),
        DashEvent(12.1, 4, "comm", "comm outage", ERROR),
        DashEvent(14.1, 4, "comm", "comm restored", NOTICE),
        DashEvent(15.2, 8, "status", "status stale (1.0s)", ERROR),
        DashEvent(12.7, 6, "statustext", "Failsafe: offboard setpoints lost", CRIT),
        DashEvent(14.7, 6, "link", "link lost (heartbeat 2.1s)", CRIT),
    ]
    events.sort(key=lambda e: e.t)
    return view, events


def recorded_source(sc: Scenario | None = None) -> RecordedSource:
    view, events = recorded_view(sc)
    return RecordedSource(view, events)
