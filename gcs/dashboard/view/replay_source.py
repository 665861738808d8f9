"""A recorded run as the dashboard's source (``gcs dashboard --replay RUN``): the same
:class:`~.state.SwarmView` and :class:`~.state.DashEvent` the live source makes, built from
the run's series at the frame of a :class:`~.replay.ReplayCursor`. No Textual.

:func:`load_run` reads a run folder (``metrics.json`` + ``series.npz``) or a
``record.mcap`` with the loaders of :mod:`gcs.records` (every failure one line: a
:class:`~gcs.records.reader.RecordError` or ``ValueError``), and the run's scenario
(``--scenario`` or ``scenarios/<name>.toml``) for the roles, the cube, D_safe and the world.
The events are the record's ``/events`` (:func:`gcs.records.events.all_events`).

What a record has no word for is shown as known: the mode is ``OFFBOARD`` (the agents'
setpoints fly every vehicle for the whole run), armed while the thrust is above zero, the
link is the record's sample rate, the QP ``fallbk`` when the step degraded (relaxed or fell
back), ``solved`` when the agent solved one, else ``inactive``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from gcs.records import events as rev
from gcs.records.cli import run_scenario
from gcs.records.export import load_record, load_run_folder
from gcs.records.reader import RecordError, read_document
from gcs.report.metrics import Series
from swarm_common.enums import QPStatus, VehicleMode
from swarm_common.scenario.model import Scenario

from .replay import ReplayCursor, series_problem
from .state import (
    DashEvent,
    SwarmView,
    VehicleRow,
    as_vec3,
    cube_edges,
    failsafe_label,
    nearest_neighbours,
)

# a record event's level (foxglove.LogLevel value) -> MAV_SEVERITY, as the event log shows it
SEVERITY = {rev.DEBUG: mavlink.MAV_SEVERITY_DEBUG, rev.INFO: mavlink.MAV_SEVERITY_INFO,
            rev.WARNING: mavlink.MAV_SEVERITY_WARNING, rev.ERROR: mavlink.MAV_SEVERITY_ERROR}
# the series' fields the replay reads, each checked to hold numbers (or booleans)
NUMERIC = ("t", "p", "v", "p_des", "z1", "thrust", "min_dist", "h_min", "solve_us",
           "fallback", "input_clipped", "alarms")


@dataclass(frozen=True)
class ReplayRun:
    """A loaded run: ``ids`` (the series' columns), its ``metrics.json`` document, the
    series and the scenario; ``name``: what the header calls it."""

    name: str
    ids: list[int]
    doc: dict[str, Any]
    series: Series
    scenario: Scenario


def load_run(path: Path, scenario: str | None = None) -> ReplayRun:
    """The run at ``path`` (a run folder or a record file) and its scenario (``scenario``:
    a TOML path, default ``scenarios/<name>.toml`` of the run's name); a RecordError or
    ValueError of one line when either is missing, truncated or foreign."""
    if path.is_file() or path.suffix == ".mcap":
        ids, ser, _ = load_record(path)
        doc = read_document(path)
    else:
        doc, ser = load_run_folder(path)
        ids = []
    n = ser.p.shape[1]
    if (why := series_problem(ser.t, ser.min_dist)) is not None:
        raise RecordError(f"{path}: {why}")
    text = [f for f in NUMERIC if getattr(ser, f).dtype.kind not in "biuf"]
    if text:
        raise RecordError(f"{path}: {', '.join(text)} not numbers")
    if not isinstance(doc.get("metrics", {}), dict):
        raise RecordError(f"{path}: its metrics are not a JSON object")
    name = doc.get("scenario")
    sc = run_scenario(scenario, name, n)  # ValueError (one line) for a bad --scenario
    if sc is None:
        raise ValueError(f"{path}: scenario {name!r} not found: give --scenario")
    if not ids:  # a run folder's columns are in scenario order
        ids = [int(i) for i in sc.ids]
    elif sorted(ids) != sorted(int(i) for i in sc.ids):
        raise ValueError(f"{path}: agents {ids}, the scenario {sc.name} has {list(sc.ids)}")
    return ReplayRun(f"{path.name} ({sc.name})", ids, doc, ser, sc)


def record_events(run: ReplayRun) -> list[DashEvent]:
    """The run's events (its record's ``/events``) as the event log's lines, by time."""
    s = run.series
    ns = np.round(np.asarray(s.t, float) * 1e9).astype(np.int64)
    try:
        events = rev.all_events(run.doc, ns, run.ids, s.fallback, s.alarms, s.input_clipped)
    except (TypeError, AttributeError) as exc:  # a metrics.json of another shape
        raise RecordError(f"{run.name}: its events cannot be read ({exc})") from None
    out = []
    for e in events:
        head, _, tail = e.name.partition("/")
        agent = int(tail) if head == "agent" and tail.isdigit() else 0
        out.append(DashEvent(e.ns / 1e9, agent, head, e.message, SEVERITY[e.level]))
    return out


def _f(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _v(a: np.ndarray) -> tuple[float, float, float] | None:
    return as_vec3(a) if np.all(np.isfinite(a)) else None


class ReplaySource:
    """The app's source over ``run``: each :meth:`poll` moves the cursor on by the wall
    time since the last one and returns the view at its frame and the events that came
    since (after :meth:`restart_events`, every event up to now)."""

    live = True  # the app polls it on its timer: playing moves with the wall clock

    def __init__(self, run: ReplayRun, clock: Callable[[], float] = time.monotonic) -> None:
        self.run = run
        self.events = record_events(run)
        self.cursor = ReplayCursor(run.series.t, run.series.min_dist,
                                   [e.t for e in self.events])
        self.clock = clock
        self._last: float | None = None
        self._shown = 0  # events handed out so far
        sc = run.scenario
        self.roles = {a.id: a.role for a in sc.agents}
        verts = sc.vertices()[[sc.index_of(i) for i in run.ids]]
        self.edges = cube_edges(run.ids, verts)
        self.d_safe = float(sc.controller.d_safe_m)
        t = np.asarray(run.series.t, float)
        self.rate_hz = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 else 0.0
        alarms = (run.doc.get("metrics") or {}).get("safety_alarms")
        self.collision_times = sorted(
            float(a["t_s"]) for a in (alarms if isinstance(alarms, list) else [])
            if isinstance(a, dict)
            and a.get("assumption") == "collision" and isinstance(a.get("t_s"), int | float))

    def close(self) -> None:
        pass

    def restart_events(self) -> None:
        """The cursor went back: the next poll hands out every event up to it again."""
        self._shown = 0

    def poll(self) -> tuple[SwarmView, list[DashEvent]]:
        now = self.clock()
        if self._last is not None:
            self.cursor.advance(now - self._last)
        self._last = now
        upto = self.cursor.event_index()
        new = self.events[self._shown:upto] if upto >= self._shown else []
        self._shown = upto
        return self.view(), new

    def view(self) -> SwarmView:
        """What the dashboard shows at the cursor's frame."""
        s, ids, k = self.run.series, self.run.ids, self.cursor.frame
        pos = {i: s.p[k, a] for a, i in enumerate(ids) if np.all(np.isfinite(s.p[k, a]))}
        nn, _ = nearest_neighbours(pos)
        method = str(self.run.doc.get("method"))
        rows, desired = [], {}
        for a, i in enumerate(ids):
            r = VehicleRow(id=i, role=self.roles[i], mode=VehicleMode.OFFBOARD,
                           hb_age=0.0, rate_hz=self.rate_hz, link_lost=False,
                           status_missing=False, status_age=0.0, method=method)
            thrust = _f(s.thrust[k, a])
            r.armed = None if thrust is None else thrust > 0.0
            r.pos, r.vel, r.p_des = _v(s.p[k, a]), _v(s.v[k, a]), _v(s.p_des[k, a])
            r.nn_dist = nn.get(i)
            if r.p_des is not None:
                desired[i] = r.p_des
                if r.pos is not None:
                    r.track_err = float(np.linalg.norm(np.subtract(r.pos, r.p_des)))
            r.est_err = _f(np.linalg.norm(s.z1[k, a] - s.p[k, a]))
            r.h_min = _f(s.h_min[k, a])
            r.qp_us = _f(s.solve_us[k, a])
            r.qp_status = (QPStatus.FALLBACK if s.fallback[k, a] else
                           QPStatus.SOLVED if (r.qp_us or 0.0) > 0.0 else QPStatus.INACTIVE)
            r.failsafe = failsafe_label(r, True, None, False, int(s.alarms[k, a]))
            rows.append(r)
        t = float(s.t[k])
        return SwarmView(
            t=t, rows=rows, desired=desired, cube_edges=self.edges, d_safe=self.d_safe,
            min_dist=self.cursor.min_dist_now,
            min_dist_history=self.cursor.history(), link="replay", zenoh="off",
            swarm=str(self.run.doc.get("scenario")), method=method, sim_time=t,
            collisions=int(np.searchsorted(self.collision_times, t, side="right")),
        )
