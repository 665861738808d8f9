"""Where the formation's mission stands, for the dashboard's mission panel and top view, and
the typed go-to's parser (``g``). No Textual, no I/O.

:func:`progress_at` reads a replica of the leaders' timeline
(:class:`swarm_common.mission.timeline.MissionTimeline`, ``FormationSteer.timeline``) at the
swarm's mission time ``t`` (s): the plan in force then, its next waypoint, the time to
arrive there, the fraction of the plan's time done and its centroid path (ENU, m).
:func:`parse_goto` reads ``"x y z"`` or ``"x, y, z, yaw"`` (m ENU, yaw deg).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from swarm_common.mission.config import MissionError
from swarm_common.mission.live import LivePlan
from swarm_common.mission.plan import MissionPlan
from swarm_common.mission.timeline import MissionTimeline

PATH_STEP_S = 0.5  # s between two samples of the planned centroid path
MAX_PATH_POINTS = 400  # a longer plan is sampled more coarsely

_SEPARATORS = re.compile(r"[,;\s]+")


@dataclass(frozen=True, eq=False)
class MissionProgress:
    """The plan in force at mission time ``t`` (s).

    ``next_index`` is the 0-based index of the next waypoint to reach (the last one once all
    are reached), of ``count`` waypoints, ``reached`` of them reached by ``t``;
    ``next_centroid`` (3,) m ENU is that waypoint's centroid (the held one while holding)
    and ``eta_s`` (s, >= 0) the time to arrive there. ``fraction`` in [0, 1] is the share
    of the plan's time, first departure to last departure, gone by. ``holding``: a hold
    command stopped the mission (the plan has no waypoints); ``finished``: the plan is over.
    ``path`` (K, 3) m: the plan's centroid sampled from its start to its end."""

    t: float
    next_index: int
    count: int
    reached: int
    next_centroid: np.ndarray
    eta_s: float
    fraction: float
    holding: bool
    finished: bool
    path: np.ndarray
    live: bool = False  # flown live by setpoints (gcs.formation.live): next = where it stops

    def line(self) -> str:
        """One line for the mission panel, e.g.
        ``waypoint 3/5 → (20.0, 0.0, 5.0) in 4.2 s · 47 % · t 31.0 s``."""
        c = "({:.1f}, {:.1f}, {:.1f})".format(*(float(x) for x in self.next_centroid))
        t = f"t {self.t:.1f} s"
        if self.live:
            if self.finished:
                return f"flown live · at rest at {c} · {t}"
            return f"flown live · stops at {c} in {self.eta_s:.1f} s unless steered on · {t}"
        if self.holding:
            return f"holding at {c} · mission paused (n: resume) · {t}"
        head, pct = f"waypoint {self.next_index + 1}/{self.count}", f"{self.fraction:.0%}"
        if self.reached == self.count:
            state = "finished" if self.finished else "at the last waypoint"
            return f"{head} {c} reached · {pct[:-1]} % · {state} · {t}"
        return f"{head} → {c} in {self.eta_s:.1f} s · {pct[:-1]} % · {t}"


@lru_cache(maxsize=8)
def live_path(plan: LivePlan) -> np.ndarray:
    """(K, 3) m: a live plan's centroid from its start to its rest, every
    :data:`PATH_STEP_S` s and at both ends. Cached per plan."""
    k = max(2, math.ceil((plan.rest_s - plan.start_s) / PATH_STEP_S) + 1)
    path = np.array([plan.centroid_at(float(t))
                     for t in np.linspace(plan.start_s, plan.rest_s, k)])
    path.setflags(write=False)
    return path


@lru_cache(maxsize=8)
def planned_path(plan: MissionPlan) -> np.ndarray:
    """(K, 3) m: ``plan``'s centroid every :data:`PATH_STEP_S` s from its first leg's start
    to its end and at each arrival (K <= :data:`MAX_PATH_POINTS`, sampled more coarsely
    beyond; both ends always in); a hold plan: (1, 3). Cached per plan (plans never change)."""
    if not plan.legs:
        return np.asarray(plan.start_pose.centroid, dtype=float).reshape(1, 3)
    t0, t1 = plan.legs[0].t0, plan.end_s
    k = min(MAX_PATH_POINTS, max(2, math.ceil((t1 - t0) / PATH_STEP_S) + 1))
    times = np.union1d(np.linspace(t0, t1, k), plan.arrival_s)
    if len(times) > MAX_PATH_POINTS:
        times = times[np.linspace(0, len(times) - 1, MAX_PATH_POINTS).round().astype(int)]
    path = np.array([plan.centroid_at(float(t)) for t in times])
    path.setflags(write=False)
    return path


def progress_at(timeline: MissionTimeline, t: float) -> MissionProgress:
    """The progress of the plan in force at mission time ``t`` (s) (class docstring)."""
    t = float(t)
    plan = timeline.plan_at(t)
    if isinstance(plan, LivePlan):
        path = live_path(plan)
        return MissionProgress(t, 0, 0, 0, path[-1], max(plan.rest_s - t, 0.0), 1.0, False,
                               t >= plan.rest_s, path, live=True)
    path = planned_path(plan)
    if not plan.legs:  # held: stays where it stopped
        return MissionProgress(t, 0, 0, 0, path[0], 0.0, 1.0, True, False, path)
    arrivals = plan.arrival_s
    count = len(arrivals)
    reached = plan.waypoint_at(t)
    nxt = min(reached, count - 1)
    t0, t1 = plan.legs[0].t0, plan.end_s
    fraction = 1.0 if t1 <= t0 else (t - t0) / (t1 - t0)
    return MissionProgress(
        t=t, next_index=nxt, count=count, reached=reached,
        next_centroid=np.asarray(plan.legs[nxt].end.centroid, dtype=float),
        eta_s=max(arrivals[nxt] - t, 0.0), fraction=min(max(fraction, 0.0), 1.0),
        holding=False, finished=t >= t1, path=path,
    )


def parse_goto(text: str) -> tuple[np.ndarray, float | None]:
    """``"x y z"`` or ``"x, y, z [yaw]"`` (optionally in ``()`` or ``[]``, yaw may end in
    ``°``) -> (centroid (3,) m ENU, yaw deg or None). Anything but 3 or 4 finite numbers
    raises :class:`MissionError` (one line)."""
    body = text.strip().strip("()[]").replace("°", " ")
    words = [w for w in _SEPARATORS.split(body) if w]
    if len(words) not in (3, 4):
        raise MissionError(f"a go-to needs 3 or 4 numbers, x y z [yaw°] (ENU, m); "
                           f"got {len(words)}")
    values: list[float] = []
    for name, word in zip(("x", "y", "z", "yaw"), words, strict=False):
        try:
            v = float(word)
        except ValueError:
            raise MissionError(f"go-to {name} = {word[:20]!r}: not a number") from None
        if not math.isfinite(v):
            raise MissionError(f"go-to {name} = {word[:20]!r}: must be finite")
        values.append(v)
    return np.array(values[:3]), (values[3] if len(values) == 4 else None)
