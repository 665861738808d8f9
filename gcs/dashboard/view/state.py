"""What the dashboard draws: a plain snapshot (:class:`SwarmView`) and its events.

A *source* turns feeds into views: :class:`LiveSource` merges the MAVLink link and the
Zenoh feed; :class:`RecordedSource` replays one fixed view (deterministic snapshots,
docs screenshots). The UI only ever sees :class:`SwarmView` and :class:`DashEvent`.

Positions are ENU (m). Where both exist, the MAVLink position is shown (that is the
ground station's own link); Zenoh truth fills in when MAVLink has none. Tracking error
is ``|p - p_des|`` with the agent's own ``p_des`` (its Status) or, without it, the cube
placed by the two leaders (bearing formations fix translation and scale only).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from swarm_common.enums import AgentAlarm, QPStatus, Role, VehicleMode

from .preflight import ParamAgreement, param_agreement
from .timeline import EventMerger, SimClock

Vec3 = tuple[float, float, float]

FAILSAFE_WORDS = ("failsafe", "fail-safe", "emergency", "terminat")


@dataclass
class VehicleRow:
    """One vehicle's line in the table (None = not known)."""

    id: int
    role: str
    mode: str = "?"
    armed: bool | None = None
    hb_age: float | None = None
    rate_hz: float = 0.0
    link_lost: bool = True
    pos: Vec3 | None = None
    vel: Vec3 | None = None
    p_des: Vec3 | None = None
    track_err: float | None = None
    est_err: float | None = None
    nn_dist: float | None = None
    h_min: float | None = None
    qp_status: str | None = None
    qp_us: float | None = None
    method: str | None = None
    status_missing: bool = True
    status_age: float | None = None
    failsafe: str = "ok"

    @property
    def is_leader(self) -> bool:
        return self.role == Role.LEADER


@dataclass
class SwarmView:
    """Everything on screen at one instant."""

    t: float  # sim time (s) now (NaN before the dashboard heard one; recorded: its time)
    rows: list[VehicleRow]
    desired: dict[int, Vec3]  # desired (cube) position per id
    cube_edges: list[tuple[int, int]]
    d_safe: float
    min_dist: float | None = None
    min_dist_history: list[float] = field(default_factory=list)
    bad_packets: int = 0
    bad_payloads: int = 0
    link: str = "-"  # e.g. "udp 127.0.0.1:14550"
    zenoh: str = "off"  # off | waiting | ok | partial
    swarm: str = "default"
    method: str = "?"
    sim_time: float | None = None
    collisions: int = 0
    params: ParamAgreement | None = None  # the vehicles' pre-flight parameters (None: not asked)
    signed: bool = False  # the GCS link signs and verifies (MAVLink 2 signing)
    rejected: int = 0  # frames rejected for their signature: here + reported by vehicles

    @property
    def flying(self) -> bool:
        """Some vehicle is armed and flies its agent's setpoints (OFFBOARD)."""
        return any(r.armed and r.mode == VehicleMode.OFFBOARD for r in self.rows)

    def row(self, agent_id: int) -> VehicleRow | None:
        for r in self.rows:
            if r.id == agent_id:
                return r
        return None


@dataclass(frozen=True)
class DashEvent:
    t: float  # sim time (s) when it arrived (NaN before any sim time was heard)
    agent: int  # 0 = swarm / ground station
    kind: str
    text: str
    severity: int = mavlink.MAV_SEVERITY_INFO  # MAV_SEVERITY: 0 emergency .. 7 debug


# -- geometry -------------------------------------------------------------------------
def cube_edges(ids: list[int], vertices: np.ndarray) -> list[tuple[int, int]]:
    """Pairs of ids whose vertices are nearest neighbours (the cube's 12 edges)."""
    n = len(ids)
    if n < 2:
        return []
    d = np.linalg.norm(vertices[:, None, :] - vertices[None, :, :], axis=-1)
    edge = float(np.min(d[np.triu_indices(n, 1)]))
    return [
        (ids[i], ids[j])
        for i in range(n)
        for j in range(i + 1, n)
        if abs(d[i, j] - edge) < 1e-6 * max(1.0, edge)
    ]


def desired_from_leaders(
    ids: list[int], vertices: np.ndarray, leader_ids: list[int], pos: dict[int, np.ndarray]
) -> dict[int, np.ndarray]:
    """The formation placed by the first two leaders: ``p*_i = c + s v_i``."""
    if len(leader_ids) < 2 or any(lid not in pos for lid in leader_ids[:2]):
        return {}
    a, b = leader_ids[:2]
    ia, ib = ids.index(a), ids.index(b)
    dv = np.linalg.norm(vertices[ib] - vertices[ia])
    if dv < 1e-9:
        return {}
    s = float(np.linalg.norm(pos[b] - pos[a]) / dv)
    c = pos[a] - s * vertices[ia]
    return {i: c + s * vertices[k] for k, i in enumerate(ids)}


def nearest_neighbours(pos: dict[int, np.ndarray]) -> tuple[dict[int, float], float | None]:
    ids = list(pos)
    if len(ids) < 2:
        return {}, None
    p = np.array([pos[i] for i in ids])
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    nn = d.min(axis=1)
    return {i: float(nn[k]) for k, i in enumerate(ids)}, float(nn.min())


def as_vec3(a: Any) -> Vec3:
    """Three floats from any indexable (numpy array, list)."""
    return (float(a[0]), float(a[1]), float(a[2]))


def failsafe_label(row: VehicleRow, zenoh_on: bool, est_health: str | None, fs_text: bool,
                   alarms: int = 0) -> str:
    """The row's failsafe cell; ``alarms``: the agent's AgentAlarm bits (docs/safety.md).
    The agent's own alarms, estimator and QP count only while its setpoints fly the
    vehicle (OFFBOARD); before, they are no failsafe of anything."""
    if row.link_lost:
        return "LINK"
    if row.mode in ("TERMINATION",):
        return "TERM"
    if fs_text:
        return "FS"
    if zenoh_on and row.status_missing:
        return "NO-OFB"
    if row.mode != VehicleMode.OFFBOARD:
        return "ok"
    if alarms & AgentAlarm.FALLBACK:
        return "FALLBACK"
    if alarms & ~AgentAlarm.DEADLOCK:
        return "ALARM"
    if alarms:
        return "STALLED"
    if est_health not in (None, "ok"):
        return f"EST:{est_health}"[:8]
    if qp_degraded(row.qp_status):
        return "QP-FB"
    return "ok"


def qp_degraded(status: str | None) -> bool:
    """True when an agent's last QP step was relaxed or fell back (unknown words: False)."""
    try:
        return status is not None and QPStatus(status).degraded
    except ValueError:  # a word this ground station does not know
        return False


# -- sources ----------------------------------------------------------------------------
class RecordedSource:
    """Replays one fixed view and its events (deterministic snapshots)."""

    live = False

    def __init__(self, view: SwarmView, events: Iterable[DashEvent] = ()) -> None:
        self.view = view
        self._events = list(events)

    def poll(self) -> tuple[SwarmView, list[DashEvent]]:
        ev, self._events = self._events, []
        return self.view, ev

    def close(self) -> None:
        pass


class LiveSource:
    """Merges a :class:`MavlinkGcs` and a :class:`ZenohFeed` (either may be None)."""

    live = True

    def __init__(
        self,
        scenario: Any,
        link: Any = None,
        feed: Any = None,
        swarm: str = "default",
        clock: Callable[[], float] = time.monotonic,
        history: int = 600,
        procs: Any = None,
    ) -> None:
        self.sc = scenario
        self.procs = procs  # optional: has dead() -> [description] (``--launch``)
        self._dead_seen: set[str] = set()
        self.link = link
        self.feed = feed
        self.swarm = swarm
        self.clock = clock
        self.t0 = clock()
        self.ids = list(scenario.ids)
        self.roles = {a.id: a.role for a in scenario.agents}
        self.vertices = scenario.vertices()
        self.edges = cube_edges(self.ids, self.vertices)
        self.d_safe = float(scenario.controller.d_safe_m)
        self.method = str(scenario.controller.method)
        self.history: deque[float] = deque(maxlen=history)
        self._fs_text: dict[int, bool] = {}
        self._init_pos = {a.id: np.asarray(a.position, float) for a in scenario.agents}
        self.sim_clock = SimClock()  # every time on screen is sim time (timeline)
        self.merger: EventMerger[DashEvent] = EventMerger()

    def close(self) -> None:
        for part in (self.link, self.feed):
            if part is not None:
                part.close()

    def _observe_sim_time(self, snap: Any) -> None:
        """Sim-time references: the truth's stamp, else the agents' status stamps."""
        if snap.truth is not None and snap.truth_time is not None:
            self.sim_clock.observe(float(snap.truth.t), snap.truth_time)
        elif snap.status:
            st, ts = max(snap.status.values(), key=lambda rec: rec[1])
            self.sim_clock.observe(float(st.t), ts)

    def poll(self) -> tuple[SwarmView, list[DashEvent]]:
        now = self.clock()
        events: list[DashEvent] = []
        veh = self.link.vehicles() if self.link is not None else {}
        snap = None
        if self.feed is not None:
            self.feed.check(now)
            snap = self.feed.snapshot()
            self._observe_sim_time(snap)
        sim_at = self.sim_clock.at
        if snap is not None:
            for e in self.feed.drain_events():
                events.append(DashEvent(sim_at(e.t), e.agent, e.kind, e.text, e.severity))
        if self.link is not None:
            for e in self.link.drain_events():
                events.append(DashEvent(sim_at(e.t), e.sysid, e.kind, e.text, e.severity))
                if e.kind == "statustext" and any(w in e.text.lower() for w in FAILSAFE_WORDS):
                    self._fs_text[e.sysid] = e.severity <= mavlink.MAV_SEVERITY_WARNING
        if self.procs is not None:
            for d in self.procs.dead():
                if d not in self._dead_seen:
                    self._dead_seen.add(d)
                    ev = DashEvent(
                        sim_at(now), 0, "process", f"exited: {d}", mavlink.MAV_SEVERITY_CRITICAL
                    )
                    events.append(ev)
        events = self.merger.push(events, now)

        truth = snap.truth if snap is not None else None
        truth_fresh = snap is not None and truth is not None and now - (snap.truth_time or 0) < 2.0
        tpos: dict[int, np.ndarray] = {}
        tvel: dict[int, np.ndarray] = {}
        if truth is not None and truth_fresh:
            for k, i in enumerate(truth.ids):
                tpos[i], tvel[i] = truth.p[k], truth.v[k]
        pos: dict[int, np.ndarray] = {}
        vel: dict[int, np.ndarray] = {}
        for i in self.ids:
            lv = veh.get(i)
            if lv is not None and lv.pos_enu is not None and not lv.lost:
                pos[i] = np.array(lv.pos_enu)
                if lv.vel_enu is not None:
                    vel[i] = np.array(lv.vel_enu)
            elif i in tpos:
                pos[i], vel[i] = tpos[i], tvel[i]
        nn, dmin = nearest_neighbours(pos)
        if dmin is not None:
            self.history.append(dmin)
        lead_pos = {i: pos.get(i, self._init_pos[i]) for i in self.sc.leader_ids}
        cube = desired_from_leaders(self.ids, self.vertices, self.sc.leader_ids, lead_pos)

        status = snap.status if snap is not None else {}
        estimate = snap.estimate if snap is not None else {}
        methods = set()
        rows: list[VehicleRow] = []
        desired: dict[int, Vec3] = {}
        for i in self.ids:
            r = VehicleRow(id=i, role=self.roles[i])
            lv = veh.get(i)
            if lv is not None:
                r.mode = lv.mode
                r.armed = lv.armed
                r.hb_age = lv.heartbeat_age(now)
                r.rate_hz = lv.rate_hz
                # the link tracker's judgement only (its timeout, on the sim clock and up to
                # what its reader has read): the UI's own clock would trip under load
                r.link_lost = lv.lost or r.hb_age is None
            elif truth is not None and truth_fresh and i in truth.ids:
                k = truth.ids.index(i)
                r.mode = truth.mode[k] if k < len(truth.mode) else "?"
                r.armed = truth.armed[k] if k < len(truth.armed) else None
                r.link_lost = self.link is not None
            if i in pos:
                r.pos = as_vec3(pos[i])
                r.nn_dist = nn.get(i)
            if i in vel:
                r.vel = as_vec3(vel[i])
            st = status.get(i)
            est_health, alarms = None, 0
            if st is not None:
                s, ts = st
                r.status_age = now - ts
                r.status_missing = snap is not None and i in snap.missing
                r.h_min = s.h_min if math.isfinite(s.h_min) else None
                r.qp_status = s.qp_status
                r.qp_us = s.qp_solve_us
                r.method = s.method
                methods.add(s.method)
                est_health, alarms = s.est_health, s.alarms
                if np.all(np.isfinite(s.p_des)) and np.any(s.p_des != 0):
                    desired[i] = as_vec3(s.p_des)
                z1 = s.z1 if np.any(s.z1 != 0) else None
                if z1 is None and i in estimate:
                    z1 = estimate[i][0].z1
                if z1 is not None and i in pos:
                    r.est_err = float(np.linalg.norm(z1 - pos[i]))
            if i not in desired and i in cube:
                desired[i] = as_vec3(cube[i])
            r.p_des = desired.get(i)
            if r.p_des is not None and r.pos is not None:
                r.track_err = float(np.linalg.norm(np.subtract(r.pos, r.p_des)))
            r.failsafe = failsafe_label(
                r, self.feed is not None, est_health, self._fs_text.get(i, False), alarms
            )
            rows.append(r)

        if self.feed is None:
            zstate = "off"
        elif not status and truth is None:
            zstate = "waiting"
        else:
            missing = snap.missing if snap is not None else []
            zstate = "ok" if not missing else f"missing {len(missing)}"
        if methods:
            method = methods.pop() if len(methods) == 1 else "mixed"
        else:
            method = self.method + "?"
        t_sim = sim_at(now)
        view = SwarmView(
            t=t_sim,
            rows=rows,
            desired=desired,
            cube_edges=self.edges,
            d_safe=self.d_safe,
            min_dist=dmin,
            min_dist_history=list(self.history),
            bad_packets=self.link.bad_packets if self.link is not None else 0,
            bad_payloads=snap.bad_payloads if snap is not None else 0,
            link=f"udp {self.link.host}:{self.link.port}" if self.link is not None else "off",
            zenoh=zstate,
            swarm=self.swarm,
            method=method,
            sim_time=t_sim if math.isfinite(t_sim) else None,
            collisions=truth.collisions if truth is not None else 0,
            signed=bool(getattr(self.link, "signed", False)),
            rejected=int(getattr(self.link, "rejected", 0)) + sum(v.rejected for v in veh.values()),
            params=(None if self.link is None or not getattr(self.link, "param_names", ())
                    else param_agreement({i: v.params for i, v in veh.items()}, self.ids,
                                         self.link.param_names)),
        )
        return view, events
